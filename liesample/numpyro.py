"""NumPyro distributions on spheres and SO(3) (``VonMisesFisher``, ``MatrixFisher``,
``Bingham``); the implementation is :mod:`liesample.interop.numpyro_distributions`."""

from liesample.interop.numpyro_distributions import *
from liesample.interop.numpyro_distributions import __all__  # noqa: F401
