"""Samplers on coadjoint orbits: the Poisson–Langevin chain, unadjusted or Metropolis-adjusted."""
