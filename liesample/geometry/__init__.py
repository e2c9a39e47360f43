"""Geometry: Lie algebras and their coadjoint moves, parameter spaces (spheres, groups, Rⁿ),
Poisson structures and the one-effect steps on the cotangent bundle ``T*G``. No randomness."""
