"""Designs: one module per method family; each returns a design object holding the gains and
the re-checked certificate, able to build its closed loop."""
