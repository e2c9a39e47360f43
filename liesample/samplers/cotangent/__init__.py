"""Samplers on ``T*G``: geometric HMC and Langevin, and the magnetic samplers, their ``Rᵈ``
fronts."""
