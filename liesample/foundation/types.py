"""Type aliases of the annotations: what the public functions take and return."""

from __future__ import annotations

from typing import Any

__all__ = ["PyTree"]

PyTree = Any
"""A pytree of arrays (an array, or a dict, tuple or named tuple of them, nested): positions on
product spaces, observables, an ``info`` record. ``Any``, as JAX itself annotates pytrees."""
