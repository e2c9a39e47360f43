"""Samplers on ``T*G``: geometric HMC and Langevin; the magnetic samplers are their ``Rᵈ`` fronts."""
