"""Canonical problems with known answers (a conformance suite every integrator and solver
runs) and :func:`check_system` for user-defined systems and laws."""
