"""Type aliases of the annotations: what the public functions take and return.

``Tree[Leaf]`` is a pytree whose leaves have the type ``Leaf``: a leaf, ``None`` (an empty
subtree), or a sequence (tuple, list, named tuple) or mapping (dict) of such trees, nested.
``PyTree`` is a tree of arrays (positions on product spaces, observables, an ``info`` record);
a tree of spaces is ``Tree[Space]``. A pytree node type registered with
``jax.tree_util.register_pytree_node`` is not a sequence or a mapping, so a checker does not
see it as a ``PyTree``: pass it with ``typing.cast(PyTree, value)``.

``PRNGKey`` is a JAX random key, new-style (``jax.random.key``) or a legacy ``uint32[2]``
array (``jax.random.PRNGKey``): both are ``jax.Array`` values.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
from jax.typing import ArrayLike

__all__ = ["LogDensityFn", "PRNGKey", "PyTree", "Tree", "TreeDef"]

type Tree[Leaf] = Leaf | Sequence[Tree[Leaf]] | Mapping[Any, Tree[Leaf]] | None
"""A pytree with leaves of type ``Leaf``: a leaf, ``None``, or a sequence or mapping of trees."""

type PyTree = Tree[ArrayLike]
"""A pytree of arrays: an array or scalar, or a tuple, list, named tuple or dict of them."""

type PRNGKey = jax.Array
"""A JAX random key (``jax.random.key(seed)`` or the legacy ``jax.random.PRNGKey(seed)``)."""

type LogDensityFn = Callable[..., ArrayLike]
"""``position ↦ log π(position)`` (up to a constant), a real scalar, JAX-traceable; a sampler
given ``model_args``/``model_kwargs`` calls it as ``logdensity_fn(position, *model_args,
**model_kwargs)``. The position
is what the sampler moves: an array, or a pytree of arrays like its space; a function annotated
for the position it is given (``jax.Array``, a dict, ...) fits."""

TreeDef = Any
"""A ``jax.tree_util.PyTreeDef`` (what ``jax.tree.structure`` returns). jaxlib's compiled
module ships no stub for that class, so a checker cannot see its methods (``num_leaves``,
``unflatten``, ``flatten_up_to``, ``==``): hold one in a name annotated ``TreeDef``."""
