"""Lattice gauge theory with the Wilson action: a system on ``T*G`` (a product of groups).

A :class:`WilsonGauge` is the first *group-product* system kind: its state is a field of group
elements (the links), not a point of a coadjoint orbit, so it is not a
:class:`~liesample.dynamics.system.LiePoissonSystem`. It declares

- ``space``: the links as a space of :mod:`liesample.geometry.spaces` (``U1`` angles of shape
  ``(d, *shape)``, or ``SU(N)`` matrices of shape ``(d, *shape, N, N)``), which is what the
  ``T*G`` samplers (:func:`liesample.geometric_hmc`) move by exact group exponentials;
- ``action(links)``: ``S/β = Σ_P w_P (1 − Re tr U_P / N)`` (``1 − cos θ_P`` for U(1)), so the
  Gibbs law is ``exp(−β S/β)`` with respect to the Haar measure of every link, and
  ``logdensity(beta)`` is the ``log π`` a ``T*G`` sampler takes; the plane weights ``w_P`` are 1
  (the isotropic action) unless the system has an ``anisotropy`` (below);
- the observables ``mean_plaquette``, ``topological_charge``, ``wilson_loop``,
  ``polyakov_loop``, ``energy_density``, and the Haar / identity starts ``hot_start`` and
  ``cold_start``;
- ``staples(links, mu)``: the sum ``A_μ(x)`` of the staples, each weighted by its plane's
  ``w_P``, so that the action is, link by link, ``−(1/N) Re tr(U_μ(x) A_μ(x))`` plus terms free
  of ``U_μ(x)`` (what the heat bath uses).

The plaquette is ``U_P = U_μ(x) U_ν(x+μ̂) U_μ(x+ν̂)† U_ν(x)†`` (``θ_μ(x) + θ_ν(x+μ̂) −
θ_μ(x+ν̂) − θ_ν(x)`` for U(1)), one per site and pair ``μ < ν``. Periodic boundaries close the
lattice into a torus; ``"open"`` keeps only the plaquettes that do not wrap (the links at the
far edge that no plaquette holds are then free, Haar-distributed).

Anisotropy. The time direction is the last lattice axis (``d − 1``, the default axis of
``polyakov_loop`` and ``wilson_loop``). With a bare anisotropy ``ξ > 0`` the action is
``S = β_s Σ_{spatial P} (1 − Re tr U_P/N) + β_t Σ_{temporal P} (…)``, ``β_s = β/ξ`` and
``β_t = β ξ`` (Karsch 1982's parameterisation: ``ξ = a_s/a_t`` at tree level), i.e. the
plane weights ``w_P = 1/ξ`` for a plane of two spatial directions and ``w_P = ξ`` for a plane
that holds the time direction; ``ξ = 1`` (the default) is the isotropic action, computed by the
very same operations (no weights are multiplied in). A 2-D lattice has only the space–time
plane, so there ``S = β ξ Σ_P (…)``. ``mean_plaquette``, ``spatial_plaquette``,
``temporal_plaquette`` and ``energy_density`` are unweighted means (observables, not the action).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike, DTypeLike

from liesample.foundation.types import PRNGKey
from liesample.foundation.validation import finite_float, prng_key
from liesample.geometry import spaces

__all__ = ["GROUPS", "WilsonGauge", "wilson_gauge"]

GROUPS = ("U1", "SU2", "SU3")
"""Names ``wilson_gauge`` takes for ``group`` (and ``"SU<N>"`` for any ``N ≥ 2``)."""


def _group_order(group) -> int:
    """1 for ``"U1"``, ``N`` for ``"SU<N>"``, or a clear error."""
    if group == "U1":
        return 1
    if isinstance(group, str) and group.startswith("SU") and group[2:].isdigit():
        n = int(group[2:])
        if n >= 2:
            return n
    raise ValueError(f"group must be 'U1', 'SU2', 'SU3' (or 'SU<N>' with N >= 2), got {group!r}")


def _lattice_shape(shape) -> tuple[int, ...]:
    if isinstance(shape, (int, np.integer)) or not isinstance(shape, (tuple, list)):
        raise TypeError(
            f"shape must be a tuple of 2 to 4 lattice extents, e.g. (8, 8), got {shape!r}"
        )
    if not 2 <= len(shape) <= 4 or not all(
        isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 2 for s in shape
    ):
        raise ValueError(
            f"shape must hold 2 to 4 integer extents, each >= 2 (e.g. (8, 8) or (8, 8, 8, 8)), "
            f"got {shape!r}"
        )
    return tuple(int(s) for s in shape)


def _index(name: str, value, size: int, what: str) -> int:
    """``value`` as an int in ``[0, size)``, or an error naming ``name`` and the range."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int (an axis of the lattice), got {value!r}")
    if not 0 <= value < size:
        raise ValueError(
            f"{name} must be {what} in 0 … {size - 1} for a {size}-dimensional lattice, got {value}"
        )
    return int(value)


def _real_dtype(dtype, name: str):
    """``dtype`` (or the default float) as a real floating dtype, or a ``TypeError``."""
    dtype = jnp.dtype(dtype or jnp.zeros(()).dtype)
    if not jnp.issubdtype(dtype, jnp.floating):
        raise TypeError(
            f"{name} must be a real floating dtype (float32 or float64; SU(N) links are then "
            f"complex of that precision), got {dtype}"
        )
    return dtype


def _dagger(u):
    return jnp.conj(jnp.swapaxes(u, -1, -2))


@dataclasses.dataclass(frozen=True)
class WilsonGauge:
    """The Wilson gauge action on a ``d``-dimensional lattice (:func:`wilson_gauge`).

    Examples
    --------
    >>> from liesample.systems import wilson_gauge
    >>> system = wilson_gauge("U1", (4, 4))
    >>> links = system.cold_start()  # every link the identity
    >>> links.shape, float(system.mean_plaquette(links)), system.num_plaquettes
    ((2, 4, 4), 1.0, 16)
    """

    group: str
    shape: tuple[int, ...]
    boundary: str = "periodic"
    anisotropy: float = 1.0

    def __post_init__(self):
        _group_order(self.group)
        object.__setattr__(self, "shape", _lattice_shape(self.shape))
        if self.boundary not in ("periodic", "open"):
            raise ValueError(f"boundary must be 'periodic' or 'open', got {self.boundary!r}")
        object.__setattr__(self, "anisotropy", _anisotropy(self.anisotropy))

    # ------------------------------------------------------------------ structure
    @property
    def n(self) -> int:
        """``N`` of ``SU(N)``; 1 for U(1)."""
        return _group_order(self.group)

    @property
    def dim(self) -> int:
        return len(self.shape)

    @property
    def abelian(self) -> bool:
        return self.n == 1

    @property
    def space(self) -> spaces.Space:
        """The links as a space: ``U1((d, *shape))`` or ``SU(N, (d, *shape))``."""
        links = (self.dim, *self.shape)
        return spaces.U1(links) if self.abelian else spaces.SU(self.n, links)

    @property
    def num_plaquettes(self) -> int:
        """Plaquettes in the action (``V d(d−1)/2`` on the torus)."""
        return int(sum(np.sum(self.plaquette_mask(mu, nu)) for mu, nu in self.planes))

    @property
    def planes(self) -> tuple[tuple[int, int], ...]:
        return tuple((mu, nu) for mu in range(self.dim) for nu in range(mu + 1, self.dim))

    @property
    def time_axis(self) -> int:
        """The time direction, ``d − 1`` (the last lattice axis; module notes)."""
        return self.dim - 1

    @property
    def spatial_planes(self) -> tuple[tuple[int, int], ...]:
        """The planes ``μ < ν`` of two spatial directions (none in 2-D)."""
        return tuple(p for p in self.planes if self.time_axis not in p)

    @property
    def temporal_planes(self) -> tuple[tuple[int, int], ...]:
        """The planes ``(μ, d − 1)`` that hold the time direction."""
        return tuple(p for p in self.planes if self.time_axis in p)

    def plane_weight(self, mu: int, nu: int) -> float:
        """``w_P`` of the plane ``(μ, ν)`` in the action: ``ξ`` if it holds the time
        direction, ``1/ξ`` if not (1 for the isotropic action)."""
        if self.anisotropy == 1.0:
            return 1.0
        return self.anisotropy if self.time_axis in (mu, nu) else 1.0 / self.anisotropy

    def check_links(self, links: ArrayLike, name: str = "links") -> None:
        """Raise unless ``links`` has the shape and dtype of this system's links (cheap: shape
        and dtype only, so it costs nothing under ``jit``; ``system.space.check`` also checks
        that a concrete field lies on the group)."""
        expected = self.space.position_array_shape
        if np.shape(links) != expected:
            kind = "angles" if self.abelian else f"{self.n}×{self.n} matrices"
            raise ValueError(
                f"{name} must have shape {expected} for {self!r} ({kind}: a direction axis of "
                f"{self.dim}, then the lattice {self.shape}), got {np.shape(links)}; build them "
                "with system.hot_start(key) or system.cold_start()"
            )
        dtype = jnp.result_type(links)
        good = jnp.issubdtype(dtype, jnp.floating if self.abelian else jnp.complexfloating)
        if not good:
            wanted = "real floating (angles)" if self.abelian else "complex (SU(N) matrices)"
            raise TypeError(f"{name} must be a {wanted} array for {self.group}, got {dtype}")

    def check_axis(self, name: str, value: object) -> int:
        """``value`` as a lattice direction ``0 … d−1``, or an error naming ``name``."""
        return _index(name, value, self.dim, "a lattice direction")

    def check_plane(self, mu: object, nu: object) -> tuple[int, int]:
        """Two distinct lattice directions, or an error naming ``mu`` and ``nu``."""
        mu, nu = self.check_axis("mu", mu), self.check_axis("nu", nu)
        if mu == nu:
            raise ValueError(f"mu and nu must be two different directions (a plane), got {mu}")
        return mu, nu

    def plaquette_mask(self, mu: int, nu: int) -> np.ndarray:
        """Which sites ``x`` carry a plaquette in the plane ``(μ, ν)`` (all on the torus)."""
        mask = np.ones(self.shape, bool)
        if self.boundary == "open":
            for axis in (mu, nu):
                index: list[slice | int] = [slice(None)] * self.dim
                index[axis] = -1
                mask[tuple(index)] = False
        return mask

    # ------------------------------------------------------------------ lattice algebra
    def shift(self, field: jax.Array, axis: int, step: int = 1) -> jax.Array:
        """``f(x + step·ê_axis)`` of a site field (periodic indexing)."""
        return jnp.roll(field, -step, axis=axis)

    def multiply(self, *factors: jax.Array) -> jax.Array:
        """The product of link fields (sum of angles for U(1))."""
        out = factors[0]
        for f in factors[1:]:
            out = out + f if self.abelian else out @ f
        return out

    def inverse(self, u: jax.Array) -> jax.Array:
        return -u if self.abelian else _dagger(u)

    def retrace(self, u: jax.Array) -> jax.Array:
        """``Re tr U / N`` (``cos θ`` for U(1))."""
        if self.abelian:
            return jnp.cos(u)
        return jnp.real(jnp.trace(u, axis1=-2, axis2=-1)) / self.n

    def plaquette(self, links: jax.Array, mu: int, nu: int) -> jax.Array:
        """``U_μν(x)`` at every site (angles for U(1))."""
        self.check_links(links)
        mu, nu = self.check_plane(mu, nu)
        u_mu, u_nu = links[mu], links[nu]
        return self.multiply(
            u_mu,
            self.shift(u_nu, mu),
            self.inverse(self.shift(u_mu, nu)),
            self.inverse(u_nu),
        )

    def staples(self, links: jax.Array, mu: int) -> jax.Array:
        """``A_μ(x)``: the sum of staples, ``Σ_P∋U_μ(x) Re tr(U_P)/N = Re tr(U_μ(x) A_μ(x))/N``.

        For U(1) a complex number ``Σ e^{iα}`` (the action of the link is ``−Re(e^{iθ} A)``)."""
        self.check_links(links)
        mu = self.check_axis("mu", mu)
        total = 0.0
        for nu in range(self.dim):
            if nu == mu:
                continue
            lo, hi = sorted((mu, nu))
            mask = jnp.asarray(self.plaquette_mask(lo, hi))
            u_mu, u_nu = links[mu], links[nu]
            up = self.multiply(
                self.shift(u_nu, mu), self.inverse(self.shift(u_mu, nu)), self.inverse(u_nu)
            )
            down = self.multiply(
                self.inverse(self.shift(self.shift(u_nu, mu), nu, -1)),
                self.inverse(self.shift(u_mu, nu, -1)),
                self.shift(u_nu, nu, -1),
            )
            up_mask, down_mask = mask, self.shift(mask, nu, -1)
            up, down = self._as_matrix(up, up_mask), self._as_matrix(down, down_mask)
            weight = self.plane_weight(mu, nu)
            if weight == 1.0:  # the isotropic sum, in its own order of additions
                total = total + up + down
            else:
                total = total + weight * (up + down)
        return cast(jax.Array, total)  # an array: every link has a plane through it

    def _as_matrix(self, u, mask):
        if self.abelian:
            return jnp.where(mask, jnp.exp(1j * u), 0.0)
        return jnp.where(mask[..., None, None], u, 0.0)

    # ------------------------------------------------------------------ action
    def action(self, links: jax.Array) -> jax.Array:
        """``S/β = Σ_P w_P (1 − Re tr U_P / N)`` (``w_P = 1`` unless anisotropic: module
        notes)."""
        return self._deficit(links, self.planes, weighted=True)

    def _deficit(self, links, planes, weighted: bool) -> jax.Array:
        """``Σ_{P in planes} (w_P) (1 − Re tr U_P / N)`` over the action's plaquettes."""
        self.check_links(links)
        total = 0.0
        for mu, nu in planes:
            mask = jnp.asarray(self.plaquette_mask(mu, nu))
            deficit = 1.0 - self.retrace(self.plaquette(links, mu, nu))
            plane = jnp.sum(jnp.where(mask, deficit, 0.0))
            weight = self.plane_weight(mu, nu) if weighted else 1.0
            total = total + (plane if weight == 1.0 else weight * plane)
        return cast(jax.Array, total)  # an array: every call has at least one plane

    def logdensity(self, beta: float) -> Callable[[jax.Array], jax.Array]:
        """``links ↦ −β S/β``: the ``log π`` (Haar measure) of a ``T*G`` sampler.

        ``β`` is any finite real: the groups are compact, so ``exp(−β S/β)`` is normalisable at
        either sign (``β < 0`` favours plaquettes far from the identity). With an anisotropy the
        action is the weighted one, ``β_s = β/ξ`` and ``β_t = βξ`` (module notes)."""
        beta = finite_float("beta", beta)
        return lambda links: -beta * self.action(links)

    # ------------------------------------------------------------------ starts
    def hot_start(self, rng_key: PRNGKey, dtype: DTypeLike | None = None) -> jax.Array:
        """Haar-random links (pure JAX: vmaps over keys); ``dtype`` real floating (the
        precision; SU(N) links are complex of it)."""
        return self.space.uniform(prng_key(rng_key), _real_dtype(dtype, "dtype"))

    def cold_start(self, dtype: DTypeLike | None = None) -> jax.Array:
        """Every link the identity (``dtype`` as for :meth:`hot_start`)."""
        dtype = _real_dtype(dtype, "dtype")
        if self.abelian:
            return jnp.zeros((self.dim, *self.shape), dtype)
        eye = jnp.eye(self.n, dtype=jnp.result_type(dtype, jnp.complex64))
        return jnp.broadcast_to(eye, (self.dim, *self.shape, self.n, self.n))

    # ------------------------------------------------------------------ observables
    def mean_plaquette(self, links: jax.Array) -> jax.Array:
        """Mean over the action's plaquettes of ``Re tr U_P / N`` (``cos θ_P`` for U(1)),
        every plane counted once whatever the anisotropy."""
        return 1.0 - self._deficit(links, self.planes, weighted=False) / self.num_plaquettes

    def spatial_plaquette(self, links: jax.Array) -> jax.Array:
        """Mean of ``Re tr U_P / N`` over the plaquettes of the spatial planes (3-D and 4-D
        lattices: a 2-D one has none)."""
        return self._plane_mean(links, self.spatial_planes, "spatial_plaquette")

    def temporal_plaquette(self, links: jax.Array) -> jax.Array:
        """Mean of ``Re tr U_P / N`` over the plaquettes of the planes that hold the time
        direction (the last axis)."""
        return self._plane_mean(links, self.temporal_planes, "temporal_plaquette")

    def _plane_mean(self, links, planes, name: str) -> jax.Array:
        if not planes:
            raise ValueError(
                f"{name} needs a plane of two spatial directions, which a {self.dim}-D lattice "
                "does not have (its one plane holds the time direction); use temporal_plaquette "
                "or mean_plaquette"
            )
        count = int(sum(np.sum(self.plaquette_mask(mu, nu)) for mu, nu in planes))
        return 1.0 - self._deficit(links, planes, weighted=False) / count

    def topological_charge(self, links: jax.Array) -> jax.Array:
        """2-D U(1): the geometric charge ``Σ_P arg(U_P) / 2π`` (an integer on the torus).

        Other groups and dimensions: the clover charge of :func:`clover_charge` (flow first,
        :func:`liesample.samplers.gauge.wilson_flow`, for a near-integer value)."""
        self.check_links(links)
        if self.abelian and self.dim == 2:
            theta = self.plaquette(links, 0, 1)
            return jnp.sum(jnp.angle(jnp.exp(1j * theta))) / (2.0 * jnp.pi)
        if self.dim == 4 and not self.abelian:
            return clover_charge(self, links)
        raise ValueError(
            f"topological_charge is defined for 2-D U(1) (geometric) and 4-D SU(N) (clover); "
            f"got group {self.group!r} in {self.dim} dimensions"
        )

    def wilson_loop(
        self, links: jax.Array, r: int, t: int, mu: int = 0, nu: int | None = None
    ) -> jax.Array:
        """Mean of ``Re tr W / N`` over the ``r × t`` rectangles in the plane ``(μ, ν)``
        (``ν`` the last axis by default: time).

        The extents are integers ``1 ≤ r < L_μ``, ``1 ≤ t < L_ν`` (a zero extent is no loop; an
        extent of the lattice size or more wraps the torus, a product of Polyakov lines rather
        than a Wilson loop: :meth:`polyakov_loop`). On the torus the mean is over every site;
        with ``boundary="open"`` over the sites whose rectangle stays inside the lattice (it
        never uses a far-edge link, which no plaquette holds)."""
        self.check_links(links)
        nu = self.dim - 1 if nu is None else nu
        mu, nu = self.check_plane(mu, nu)
        r, t = self._extent("r", r, mu), self._extent("t", t, nu)
        bottom = self._line(links[mu], mu, r)
        right = self.shift(self._line(links[nu], nu, t), mu, r)
        top = self.shift(self._line(links[mu], mu, r), nu, t)
        left = self._line(links[nu], nu, t)
        loop = self.multiply(bottom, right, self.inverse(top), self.inverse(left))
        if self.boundary == "periodic":
            return jnp.mean(self.retrace(loop))
        inside = np.ones(self.shape, bool)
        for axis, extent in ((mu, r), (nu, t)):
            index = [slice(None)] * self.dim
            index[axis] = slice(self.shape[axis] - extent, None)
            inside[tuple(index)] = False
        return jnp.sum(jnp.where(inside, self.retrace(loop), 0.0)) / np.sum(inside)

    def _extent(self, name: str, value, axis: int) -> int:
        """A loop extent along ``axis``: an int in ``1 … L − 1``, or an error naming it."""
        size = self.shape[axis]
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int (a loop extent), got {value!r}")
        if not 1 <= value < size:
            raise ValueError(
                f"{name} must be an extent in 1 … {size - 1} along direction {axis} (size "
                f"{size}), got {value}: a zero extent is no loop, and one of {size} or more wraps "
                "the lattice (for lines that close around it use polyakov_loop)"
            )
        return int(value)

    def _line(self, link, axis, length):
        """``U(x) U(x+ê) … U(x+(length−1)ê)`` along ``axis`` at every site."""
        out = link
        for k in range(1, length):
            out = self.multiply(out, self.shift(link, axis, k))
        return out

    def polyakov_loop(self, links: jax.Array, axis: int | None = None) -> jax.Array:
        """Mean over the spatial sites of ``tr Π_t U_t(x, t) / N`` (complex), ``axis`` the time
        direction (the last by default); needs a periodic lattice."""
        self.check_links(links)
        axis = self.check_axis("axis", self.dim - 1 if axis is None else axis)
        if self.boundary != "periodic":
            raise ValueError(
                "polyakov_loop needs boundary='periodic': on an open lattice a line along the "
                "time direction does not close (its far-edge link belongs to no plaquette); "
                "use wilson_loop, or build the system with boundary='periodic'"
            )
        line = self._line(links[axis], axis, self.shape[axis])
        value = jnp.exp(1j * line) if self.abelian else jnp.trace(line, axis1=-2, axis2=-1) / self.n
        return jnp.mean(jnp.take(value, 0, axis=axis))

    def energy_density(self, links: jax.Array) -> jax.Array:
        """``E = 2 Σ_{μ<ν} Re tr(1 − U_μν) / V`` per site in Lüscher's normalisation
        (``t² E`` defines ``t₀``: ``t₀² ⟨E(t₀)⟩ = 0.3``, the reference chosen for SU(3)); the
        same sum for every group, U(1) included (``N = 1``: ``2 Σ (1 − cos θ_μν) / V``); every
        plane counted once whatever the anisotropy."""
        deficit = self._deficit(links, self.planes, weighted=False)
        return 2.0 * self.n * deficit / math.prod(self.shape)


def clover_charge(system: WilsonGauge, links: jax.Array) -> jax.Array:
    """The clover topological charge ``Q = (1/32π²) Σ_x ε_μνρσ tr(F_μν F_ρσ)`` of a 4-D SU(N)
    field, ``F_μν`` the anti-Hermitian traceless part of the four-leaf clover over 4 (a plain
    observable: integer-valued only after smoothing, e.g. the Wilson flow)."""
    field = {}
    for mu, nu in system.planes:
        leaves = 0.0
        for s_mu, s_nu in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
            leaves = leaves + _leaf(system, links, mu, nu, s_mu, s_nu)
        c = leaves / 4.0
        a = 0.5 * (c - _dagger(c))
        eye = jnp.eye(system.n)
        field[mu, nu] = a - jnp.trace(a, axis1=-2, axis2=-1)[..., None, None] * eye / system.n
    tr = lambda a, b: jnp.real(jnp.trace(a @ b, axis1=-2, axis2=-1))
    density = (
        tr(field[0, 1], field[2, 3]) - tr(field[0, 2], field[1, 3]) + tr(field[0, 3], field[1, 2])
    )
    # F = i a² F_herm for the anti-Hermitian clover F, hence the sign
    return -jnp.sum(density) * 8.0 / (32.0 * jnp.pi**2)


def _leaf(system, links, mu, nu, s_mu, s_nu):
    """The plaquette from ``x`` going ``s_μ ê_μ`` then ``s_ν ê_ν`` (and back), oriented as the
    ``(μ, ν)`` plaquette."""

    def step(axis, sign, at):
        # the link from `at` to `at + sign ê_axis`, as a field over x (at: offsets dict)
        field = links[axis]
        for ax, k in at.items():
            field = system.shift(field, ax, k)
        if sign > 0:
            return field
        return _dagger(system.shift(field, axis, -1))

    p1 = step(mu, s_mu, {})
    p2 = step(nu, s_nu, {mu: s_mu})
    p3 = step(mu, -s_mu, {mu: s_mu, nu: s_nu})
    p4 = step(nu, -s_nu, {nu: s_nu})
    loop = p1 @ p2 @ p3 @ p4
    return loop if s_mu * s_nu > 0 else _dagger(loop)


def _anisotropy(value: object) -> float:
    """``ξ`` as a finite float ``> 0``, or an error naming ``anisotropy``."""
    try:
        xi = finite_float("anisotropy", value, positive=True)
    except (TypeError, ValueError) as error:
        raise type(error)(
            f"{error} (the bare anisotropy ξ of β_s = β/ξ, β_t = βξ: a finite number > 0, "
            "e.g. anisotropy=1.0 for the isotropic action or 2.0 for a time spacing half the "
            "spatial one)"
        ) from None
    return xi


def wilson_gauge(
    group: str, shape: Sequence[int], boundary: str = "periodic", anisotropy: float = 1.0
) -> WilsonGauge:
    """The Wilson gauge action ``S = β Σ_P (1 − Re tr U_P / N)`` on a lattice.

    Parameters
    ----------
    group : str
        ``"U1"`` (links are angles, shape ``(d, *shape)``), ``"SU2"``, ``"SU3"`` or
        ``"SU<N>"`` (complex matrices, shape ``(d, *shape, N, N)``).
    shape : tuple of int
        The lattice extents, 2 to 4 of them, each ``>= 2`` (the heat bath's checkerboard needs
        even extents on the torus).
    boundary : str
        ``"periodic"`` (a torus, default) or ``"open"`` (only the plaquettes that do not
        wrap).
    anisotropy : float
        The bare anisotropy ``ξ > 0``: the action becomes
        ``β/ξ Σ_{spatial P} (…) + βξ Σ_{temporal P} (…)``, time the last axis (module notes);
        ``1.0`` (default) is the isotropic action. Every sampler (heat bath, over-relaxation,
        HMC) samples the weighted law; the Wilson flow uses the isotropic action.

    Returns
    -------
    WilsonGauge
        Sample it with :func:`liesample.recommended_sampler` (heat bath with over-relaxation,
        :func:`liesample.wilson_heat_bath`) or with :func:`liesample.geometric_hmc` on
        ``system.space`` with ``system.logdensity(beta)``.

    Examples
    --------
    >>> from liesample.systems import wilson_gauge
    >>> system = wilson_gauge("SU2", (4, 4))
    >>> system.hot_start(jax.random.key(0)).shape  # (d, *shape, N, N), Haar-random links
    (2, 4, 4, 2, 2)
    >>> sampler = liesample.recommended_sampler(system, beta=2.0)  # heat bath, over-relaxation
    >>> anisotropic = wilson_gauge("SU2", (4, 4, 4, 4), anisotropy=2.0)  # β_s = β/2, β_t = 2β
    >>> anisotropic.plane_weight(0, 1), anisotropic.plane_weight(0, 3)
    (0.5, 2.0)
    """
    shape = cast(tuple[int, ...], shape)  # checked as a tuple there
    return WilsonGauge(group, shape, boundary, anisotropy)


jax.tree_util.register_static(WilsonGauge)
