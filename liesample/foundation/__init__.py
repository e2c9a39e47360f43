"""Foundation: argument checks and the one compile path (``liesample.jit``)."""
