"""The NumPyro MCMC kernel ``GeometricHMC``; the implementation is
:mod:`liesample.interop.numpyro_kernel`."""

# A shim: it re-exports the implementation's public names, and its __all__ (imported below).
from liesample.interop.numpyro_kernel import *  # noqa: F403
from liesample.interop.numpyro_kernel import __all__  # noqa: F401
