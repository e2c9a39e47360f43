"""Samplers, BlackJAX-shaped (``init``, ``build_kernel``, ``as_top_level_api``), by phase space:

- ``orbit/``: on coadjoint orbits (``lie_poisson_langevin``, ``adjusted_lie_poisson``;
  ``vortex_metropolis``, exact single-vortex moves for point vortices);
- ``cotangent/``: on ``T*G`` for products of spheres, groups and ``Rⁿ`` (``geometric_hmc``,
  ``geometric_langevin``; ``magnetic_hmc`` and ``magnetic_langevin`` are their ``Rᵈ`` fronts);
- ``spins/``: the physicists' spin-lattice baselines.

Every sampler's ``info`` follows one contract (:mod:`liesample.samplers.contract`).
"""
