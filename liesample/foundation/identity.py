"""Systems equal by value: two systems built by one factory from equal arguments are equal and
hash equal, so that every compiled program keyed by a system (``jax.jit``'s static arguments,
the runner's programs) serves both.

A system closes over functions (its Hamiltonian, its noise), which Python compares by identity;
two calls of ``rigid_body((1.0, 2.0, 4.0))`` would otherwise be two systems and compile two
programs. :func:`by_value` wraps a factory so that the object it returns records its
:func:`recipe`: the factory's name and its arguments in a canonical hashable form
(:func:`canonical`), together with the one process setting that changes what a factory builds
(``jax_enable_x64``: the dtype of its arrays). :class:`ValueIdentity` gives a class the
equality and hash of its recipe; an object without one (a system a user declared by hand, or
one derived by ``dataclasses.replace``) keeps the identity of an object.

Arguments that cannot be put in canonical form (a traced array, an unhashable object) give no
recipe: the system is then compared by identity, which is always correct, only slower to reuse.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Mapping

import jax
import numpy as np

from liesample.foundation.compile import jit

__all__ = ["Program", "ValueIdentity", "by_value", "canonical", "recipe", "run_program"]

RECIPE = "_liesample_recipe"
"""The attribute holding an object's recipe (set once, by :func:`by_value`)."""


class _NotCanonical(Exception):
    """An argument without a canonical hashable form."""


def canonical(value):
    """``value`` as a hashable object that is equal exactly when the values are: NumPy and
    concrete JAX arrays by dtype, shape and bytes; lists, tuples and dicts element by element;
    numbers, strings and ``None`` as they are; any other hashable object (a function, an
    algebra) as itself, by its own equality. Raises ``TypeError`` for a traced array or an
    unhashable object."""
    try:
        return _canonical(value)
    except _NotCanonical as error:
        raise TypeError(str(error)) from None


def _canonical(value, held: bool = False):
    """:func:`canonical`; ``held``: the caller keeps ``value`` alive, so an unhashable object
    may stand as its identity (an ``id`` is unique while its object lives)."""
    if value is None or isinstance(value, (bool, int, float, complex, str, bytes)):
        return (type(value).__name__, value)
    if isinstance(value, (np.ndarray, np.generic, jax.Array)):
        try:
            array = np.asarray(value)
        except jax.errors.TracerArrayConversionError:
            raise _NotCanonical("a traced array has no value to compare") from None
        return ("array", array.dtype.str, array.shape, array.tobytes())
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, tuple(_canonical(v, held) for v in value))
    if isinstance(value, Mapping):
        items = ((repr(k), _canonical(v, held)) for k, v in value.items())
        return ("mapping", tuple(sorted(items)))
    try:
        hash(value)
    except TypeError:
        if held:
            return ("id", id(value))
        raise _NotCanonical(f"an unhashable {type(value).__name__}") from None
    return ("object", value)


def recipe(obj) -> tuple | None:
    """The recipe :func:`by_value` recorded on ``obj``, or ``None``."""
    return getattr(obj, RECIPE, None)


def by_value(factory: Callable) -> Callable:
    """``factory`` whose result records its recipe (the module docstring): the factory's
    qualified name, its bound arguments with defaults applied, in canonical form, and whether
    float64 is on. Arguments without a canonical form record none."""
    signature = inspect.signature(factory)
    name = f"{factory.__module__}.{factory.__qualname__}"

    @functools.wraps(factory)
    def build(*args, **kwargs):
        result = factory(*args, **kwargs)
        try:
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            arguments = tuple((k, _canonical(v)) for k, v in bound.arguments.items())
        except (_NotCanonical, TypeError):
            return result
        object.__setattr__(result, RECIPE, (name, arguments, bool(jax.config.jax_enable_x64)))
        return result

    return build


class ValueIdentity:
    """Equality and hash by recipe (:func:`by_value`), falling back to identity.

    Mix in before a dataclass declared with ``eq=False`` (which then keeps these methods)."""

    def __eq__(self, other):
        if self is other:
            return True
        mine = recipe(self)
        return mine is not None and type(other) is type(self) and mine == recipe(other)

    def __hash__(self):
        mine = recipe(self)
        return object.__hash__(self) if mine is None else hash((type(self), mine))


class Program:
    """A computation that closures would rebuild on every call, as a value: ``make(*static)``
    returns the function of the traced arguments, and two programs of equal ``make`` (a module
    level function) and canonically equal ``static`` (:func:`canonical`; an unhashable object,
    such as a sampler's API object, by identity) are equal, so :func:`run_program` compiles one
    program for both. A traced ``static`` makes the program equal only to itself."""

    __slots__ = ("_key", "make", "static")

    def __init__(self, make: Callable, *static):
        self.make, self.static = make, static
        try:  # the program holds its callables: an unhashable one stands as its identity
            self._key = _canonical((make, static), held=True)
        except _NotCanonical:
            self._key = None

    @property
    def by_value(self) -> bool:
        """Whether the program compares by value (its ``static`` has a canonical form)."""
        return self._key is not None

    def __eq__(self, other):
        if self is other:
            return True
        return isinstance(other, Program) and self._key is not None and self._key == other._key

    def __hash__(self):
        return object.__hash__(self) if self._key is None else hash(self._key)

    def __call__(self, *traced):
        return self.make(*self.static)(*traced)


def run_program(program: Program, *traced):
    """``program(*traced)`` compiled once per equal program and argument shapes
    (``liesample.jit`` with ``program`` static)."""
    return _run(*traced, program=program)


@functools.partial(jit, static_argnames="program")
def _run(*traced, program):
    return program(*traced)
