"""NumPyro distributions on spheres and SO(3) (``VonMisesFisher``, ``MatrixFisher``,
``Bingham``); the implementation is :mod:`liesample.interop.numpyro_distributions`."""

# A shim: it re-exports the implementation's public names, and its __all__ (imported below).
from liesample.interop.numpyro_distributions import *  # noqa: F403
from liesample.interop.numpyro_distributions import __all__  # noqa: F401
