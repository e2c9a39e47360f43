"""The NumPyro MCMC kernel ``GeometricHMC``; the implementation is
:mod:`liesample.interop.numpyro_kernel`."""

from liesample.interop.numpyro_kernel import *
from liesample.interop.numpyro_kernel import __all__  # noqa: F401
