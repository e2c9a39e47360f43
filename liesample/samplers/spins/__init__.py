"""Spin-lattice samplers: exact heat bath with over-relaxation, single-spin Metropolis, Wolff."""
