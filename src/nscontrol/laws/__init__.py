"""Nonsmooth laws: set-valued maximal monotone maps (relay, normal cones, complementarity,
Coulomb friction, monotone functions, products), their resolvents and complementarity forms,
and impact laws (Newton restitution, single and multi-contact)."""
