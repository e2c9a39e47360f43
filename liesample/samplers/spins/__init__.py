"""Spin-lattice samplers: exact heat bath with over-relaxation, single-spin Metropolis, and
cluster moves (Swendsen–Wang, Wolff)."""
