"""What made a run: the fingerprint stored in its file and checked when it is resumed.

A resumed run must continue the same chains under the same law, or the file would splice two
laws. :func:`run_fingerprint` records, as named fields, what is known before the warm-up: the
sampler's kind and every setting it declares (β, σ, step size, mass, integrator and scheme,
noise block size, stability mode, …), the key, a hash of the starts, ``num_warmup``,
``thinning``, the recorded variables and a hash of the observables' computation.
:func:`adapted_fingerprint` adds, after the warm-up, the settings the warm-up chose (prefixed
``adapted.``) and a hash of the step's jaxpr at the first start: the computation itself, so
that a change a sampler does not declare in its settings (the system's parameters such as the
inertia, a log-density, a mass matrix) is refused too.

Not covered: the JAX/XLA version and the device (they may change the last bits of the draws,
not the law), and anything a step reads that is not in its traced computation (a Python global
read only when the step is first traced is in it; a callback's behaviour is not).
"""

from __future__ import annotations

import hashlib
import json
import re

import jax
import jax.numpy as jnp
import numpy as np

FORMAT = "liesample-run-3"
"""The file format this fingerprint belongs to (stored as the field ``format``)."""


def _plain(value):
    """A setting as a JSON value: numbers, strings, booleans and None as they are; small arrays
    as lists; larger ones (a mass matrix) as a hash of their bytes."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float, np.integer, np.floating, np.bool_)):
        return value.item() if hasattr(value, "item") else value
    try:
        array = np.asarray(value)
    except Exception:
        return repr(value)
    if array.dtype.kind in "biufc":
        if array.size <= 8:
            return json.loads(json.dumps(array.tolist(), default=str))
        return f"sha256:{_digest([array])}"
    return repr(value)


def _digest(arrays, text: str = "") -> str:
    digest = hashlib.sha256(text.encode())
    for array in arrays:
        array = np.ascontiguousarray(np.asarray(array))
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def key_data(rng_key) -> list:
    """The raw data of ``rng_key`` (typed or legacy) as a list of integers."""
    if jnp.issubdtype(rng_key.dtype, jax.dtypes.prng_key):
        rng_key = jax.random.key_data(rng_key)
    return np.asarray(rng_key).reshape(-1).tolist()


def jaxpr_hash(function, *args) -> str:
    """A hash of ``function``'s jaxpr at ``args`` and of the constants it closes over (memory
    addresses in its text removed, so that it is the same in every process)."""
    closed = jax.make_jaxpr(function)(*args)
    text = re.sub(r" at 0x[0-9a-fA-F]+", "", str(closed.jaxpr))
    return _digest([np.asarray(c) for c in closed.consts if hasattr(c, "shape")], text)


def sampler_kind(algorithm, settings) -> str:
    """The sampler's name from its settings, else the qualified name of its step function."""
    name = settings.get("sampler")
    if name:
        return str(name)
    step = getattr(algorithm, "step", None)
    return f"{getattr(step, '__module__', '?')}.{getattr(step, '__qualname__', type(step))}"


def run_fingerprint(
    algorithm,
    settings,
    *,
    rng_key,
    initial_positions,
    num_warmup,
    thinning,
    keep_positions,
    observe,
    log_likelihood,
    variables,
    names,
) -> dict:
    """The named fields known before the warm-up (see the module's docstring).

    ``variables``: the recorded variables' names and dims in the ``DataTree``
    (``{group/name: dims}``); ``observe``: the observables' function of one position, or
    ``None``; ``log_likelihood``: the pointwise log-likelihoods' function, or ``None``;
    ``names``: the ``[var_name, event_dims]`` that named them (adopted on resume)."""
    first = jax.tree.map(lambda leaf: jnp.asarray(leaf)[0], initial_positions)
    fields = {
        "format": FORMAT,
        "sampler": sampler_kind(algorithm, settings),
        **{name: _plain(value) for name, value in sorted(settings.items()) if name != "sampler"},
        "rng_key": key_data(rng_key),
        "initial_positions_sha256": _digest(
            jax.tree.leaves(initial_positions), str(jax.tree.structure(initial_positions))
        ),
        "num_warmup": int(num_warmup),
        "thinning": int(thinning),
        "keep_positions": bool(keep_positions),
        "variables": json.dumps(variables, sort_keys=True),
        "names": json.dumps(names),
        "observables_jaxpr_sha256": None if observe is None else jaxpr_hash(observe, first),
        "log_likelihood_jaxpr_sha256": (
            None if log_likelihood is None else jaxpr_hash(log_likelihood, first)
        ),
    }
    return fields


def adapted_fingerprint(sampler, state, rng_key) -> dict:
    """The fields fixed by the warm-up: the sampler's settings after it (``adapted.<name>``) and
    the hash of its step's jaxpr at one chain's ``state`` and key."""
    fields = {f"adapted.{name}": _plain(v) for name, v in sorted(sampler.settings.items())}
    fields["step_jaxpr_sha256"] = jaxpr_hash(sampler.step, rng_key, state)
    return fields


def differences(saved: dict, now: dict, required=()) -> list[str]:
    """``"different <field> (saved <value>, now <value>)"`` for each field of ``now`` that
    ``saved`` records otherwise, or lacks when the field is ``required``. (A sampler may add
    derived values to its settings when its starts are checked, so the fields read before
    that are compared where both record them; the settings after the warm-up, ``adapted.*``,
    are required.)"""
    missing = object()
    found = []
    for name, value in now.items():
        before = saved.get(name, missing)
        if before is missing and name not in required:
            continue
        if before is missing:
            found.append(f"different {name} (not recorded in the file, now {value!r})")
        elif json.dumps(before) != json.dumps(value):
            found.append(
                f"different {name} (saved {before!r}, now {value!r}){_MEANING.get(name, '')}"
            )
    return found


_MEANING = {
    "step_jaxpr_sha256": (
        ": the step computes something else (the system's parameters, the log-density, or a "
        "setting the sampler does not record)"
    ),
    "observables_jaxpr_sha256": ": the observables compute something else",
    "log_likelihood_jaxpr_sha256": ": the log-likelihoods compute something else",
}
