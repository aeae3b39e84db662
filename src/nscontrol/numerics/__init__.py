"""Numerical kernels: complementarity solvers (:mod:`.lcp`), exact LTI propagation and root
location (:mod:`.lti`), LMI helpers on CVXPY (:mod:`.lmi`)."""
