"""Analysis: observability, convergence, periodic orbits, Floquet multipliers, sweeps of
trajectories against a theorem's claim."""
