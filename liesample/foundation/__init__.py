"""Foundation: argument checks, the one compile path (``liesample.jit``) and JAX's persistent
compilation cache, which loading this package turns on unless the process chose otherwise
(:mod:`liesample.foundation.cache`)."""

from liesample.foundation.cache import enable_compilation_cache as _enable_compilation_cache

_enable_compilation_cache()
