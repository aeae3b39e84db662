"""Numerical kernels: complementarity solvers (:mod:`.lcp`), exact LTI propagation and root
location (:mod:`.lti`), LMI helpers on CVXPY and the Lyapunov re-check (:mod:`.lmi`),
balancing and scaling (:mod:`.scaling`), observability tests
(:mod:`~nscontrol.numerics.observability`), central differences (:mod:`.differences`)."""
