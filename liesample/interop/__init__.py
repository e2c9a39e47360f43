"""Interoperability: NumPyro distributions on spheres and SO(3), and a NumPyro MCMC kernel.
Needs NumPyro (``pip install 'liesample[numpyro]'``)."""
