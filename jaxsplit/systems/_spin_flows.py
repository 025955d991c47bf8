"""Exact flows of the pieces of a spin-lattice Hamiltonian, vectorised over a lattice.

Convention (``_spin_lattice``): {S_i^a, S_j^b} = δ_ij ε_abc S_i^c, so Ṡ_i = ∂H/∂S_i × S_i:
every piece below turns each spin about an angular velocity ω_i that is constant along the
piece's flow, S_i(t) = exp(t hat ω_i) S_i (``turn``, Rodrigues).

* Exchange bond H = −J' S_i·R S_j (R = exp(hat τ), τ the bond's twist; τ = 0: Heisenberg).
  With T = R S_j the pair (S_i, T) moves as a Heisenberg bond: M = S_i + T is conserved and
  both turn with ω = −J' M; then S_j = Rᵀ T. (``BondExchange``)
* Ising bond H = −c (n·S_i)(n·S_j): n·S_i, n·S_j conserved, ω_i = −c (n·S_j) n,
  ω_j = −c (n·S_i) n. (``BondIsing``)
* Site pieces: Zeeman H = −B·S_i, ω_i = −B; uniaxial H = −K (n·S_i)², ω_i = −2K (n·S_i) n.
  (``SiteRotation``)

A colour's bonds share no site, so one call turns all of them at once, written per site:
each spin turns about an ω built from itself and its partner in the colour (one gather by a
static index array; a site the colour misses has zero coupling): no scatter, one turn of
the whole (N, 3) array.

Reference schemes that are *not* splittings into Hamiltonian flows (they are audited, not
trusted): ``FrozenField`` turns a set of sites about the local field −∂H/∂S_i ... with the
other spins frozen (``"sublattice"`` for a sublattice, ``"sweep"`` for one site).
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core._flows import AbstractFlow


class StaticIndex:
    """A NumPy integer array as a hashable static value (compared by content): a flow's site
    indices become constants of the compiled program."""

    __slots__ = ("_key", "array")

    def __init__(self, array):
        self.array = np.asarray(array, dtype=np.int32)
        self.array.setflags(write=False)
        self._key = (self.array.shape, self.array.tobytes())

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, StaticIndex) and self._key == other._key

    def __len__(self):
        return len(self.array)

    def __repr__(self):
        return f"StaticIndex({len(self.array)})"


def turn(x, omega, axis: int = -1):
    """exp(hat ω) x for angle vectors ω (..., 3): x + a ω×x + b ω×(ω×x) with φ = |ω|,
    a = sin φ/φ = 2 sin(φ/2) cos(φ/2)/φ, b = (1 − cos φ)/φ² = 2 sin²(φ/2)/φ². φ is taken as
    √(ω·ω + tiny) (tiny the dtype's smallest normal number), so at ω = 0 (an antiparallel pair,
    a spin along its field) the map is the identity and its derivatives are finite; a and b
    lose no digits for small φ (their derivatives' rounding is O(ε/φ), multiplied by ω).
    ``axis``: the components' axis (-1; a components-first state of ``_spin_pairs``: its own)."""
    phi = jnp.sqrt(jnp.sum(omega * omega, axis=axis, keepdims=True) + jnp.finfo(omega.dtype).tiny)
    s, c = jnp.sin(phi / 2), jnp.cos(phi / 2)
    s_phi = (s + s) / phi
    wx = jnp.cross(omega, x, axis=axis)
    # the increment first, then one addition: one rounding at the size of x (|S_i| is a random
    # walk of these roundings over a long run; two additions made it √2 larger)
    return x + ((s_phi * c) * wx + (0.5 * s_phi * s_phi) * jnp.cross(omega, wx, axis=axis))


def as_sites(x, n_sites: int):
    """(x as (..., N, 3), the function that restores x's shape)."""
    shape = x.shape
    flat = x.reshape(shape[: len(shape) - 1 - _site_axes(shape, n_sites)] + (n_sites, 3))
    return flat, lambda y: y.reshape(shape)


def _site_axes(shape, n_sites: int) -> int:
    """How many axes before the trailing 3 hold the sites (1 for (N, 3), d for a lattice shape)."""
    size = 1
    for k in range(2, len(shape) + 1):
        size *= shape[-k]
        if size == n_sites:
            return k - 1
    raise ValueError(f"a state of shape {shape} does not hold {n_sites} spins")


def partners(n_sites: int, pairs) -> np.ndarray:
    """The partner of every site in a matching (itself where unmatched)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    out = np.arange(n_sites)
    out[pairs[:, 0]], out[pairs[:, 1]] = pairs[:, 1], pairs[:, 0]
    return out


def per_site(n_sites: int, pairs, first, second=None, fill=0.0):
    """A per-bond value (B_c, ...) spread to the sites: ``first`` on the bonds' first ends,
    ``second`` (default the same) on their second ends, ``fill`` on unmatched sites."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    first = jnp.asarray(first)
    second = first if second is None else jnp.asarray(second)
    out = jnp.full((n_sites,) + first.shape[1:], fill, dtype=first.dtype)
    return out.at[pairs[:, 0]].set(first).at[pairs[:, 1]].set(second)  # built once, outside the step


class _Colour(AbstractFlow):
    """One colour of bonds (a matching) written per site: each site's partner (itself when
    unmatched, with zero coupling: exp(hat 0) is the identity), gathered once per call."""

    partner: StaticIndex = eqx.field(static=True)

    def _partner_of(self, s):
        return jnp.take(s, self.partner.array, axis=-2)


class BondExchange(_Colour):
    """Exact flow of Σ_b −J'_b S_i·exp(hat τ_b) S_j over the bonds of one colour. Per site: the
    first end turns with ω = −J' (S_i + exp(hat τ) S_j), the second with
    ω = −J' (S_j + exp(−hat τ) S_i) (the first end's ω seen through exp(−hat τ)): the pair
    rotation of the module docstring. ``coupling`` (N,) J' (0 off the colour), ``twist``
    (N, 3) ±τ or None (Heisenberg)."""

    coupling: jax.Array
    twist: jax.Array | None

    def __call__(self, state, t):
        s, restore = as_sites(state, len(self.partner))
        other = self._partner_of(s)
        if self.twist is not None:
            other = turn(other, jnp.asarray(self.twist, s.dtype))
        c = jnp.asarray(self.coupling, s.dtype)[:, None]
        return restore(turn(s, (-t * c) * (s + other)))


class BondIsing(_Colour):
    """Exact flow of Σ_b −c_b (n_b·S_i)(n_b·S_j) over one colour: per site ω_i = −c (n·S_j) n.
    ``coupling`` (N,) c (0 off the colour), ``axis`` (N, 3) or (3,) unit n."""

    coupling: jax.Array
    axis: jax.Array

    def __call__(self, state, t):
        s, restore = as_sites(state, len(self.partner))
        n = jnp.asarray(self.axis, s.dtype)
        c = jnp.asarray(self.coupling, s.dtype)[:, None]
        along = jnp.sum(n * self._partner_of(s), axis=-1, keepdims=True)
        return restore(turn(s, (-t * c * along) * n))


class SiteRotation(AbstractFlow):
    """Exact flow of a single-site piece: Zeeman (``anisotropy`` None: ω_i = −B, ``vector``
    B (3,) or (N, 3)) or uniaxial anisotropy (ω_i = −2K_i (n_i·S_i) n_i, ``anisotropy`` K
    (N,), ``vector`` n (N, 3) or (3,)). ``shape``: the lattice's shape where the bond split
    runs components first (``_spin_pairs.Components``), else None."""

    vector: jax.Array
    anisotropy: jax.Array | None
    n_sites: int = eqx.field(static=True)
    shape: tuple | None = eqx.field(static=True, default=None)

    def __call__(self, state, t):
        from ._spin_pairs import Components, PairLayout

        if isinstance(state, Components):  # components first: (..., 3, L_1, ..., L_d)
            s, axis = state.array, -1 - len(self.shape)
            v, k = self._first(jnp.asarray(self.vector, s.dtype), 3), None
            if self.anisotropy is not None:
                k = jnp.expand_dims(self._first(jnp.asarray(self.anisotropy, s.dtype), 0), axis)
            return Components(self._turn(s, v, k, t, axis))
        if self.shape is not None:  # the user's layout, where the bond split needs components first
            layout = PairLayout(self.shape)
            return layout.out_of(self(layout.into(state), t), state)
        s, restore = as_sites(state, self.n_sites)
        v = jnp.asarray(self.vector, s.dtype)
        k = None if self.anisotropy is None else jnp.asarray(self.anisotropy, s.dtype)[..., None]
        return restore(self._turn(s, v, k, t, -1))

    def _first(self, value, width: int):
        """A per-site parameter (N,) or (N, 3), or a shared one, broadcastable against (3, *shape)."""
        d = len(self.shape)
        if value.ndim == (1 if width else 0):  # shared
            return value.reshape(value.shape + (1,) * d)
        value = value.reshape(self.shape + value.shape[1:])
        return jnp.moveaxis(value, -1, 0) if width else value

    @staticmethod
    def _turn(s, v, k, t, axis):
        if k is None:
            omega = jnp.broadcast_to(-t * v, s.shape)
        else:
            omega = (-2 * t * k * jnp.sum(v * s, axis=axis, keepdims=True)) * v
        return turn(s, omega, axis)


class FrozenField(AbstractFlow):
    """The sites ``sites`` turn about their local field with every other spin frozen:
    ω_i = ∂H/∂S_i at the current state (Ṡ_i = ∂H/∂S_i × S_i), the rest unchanged. A group
    flow when the field of those sites does not depend on themselves (no anisotropy on
    them, no bond inside the set: a sublattice, or one site without anisotropy); otherwise
    a first-order map (``group`` False). ``energy`` is a system's Hamiltonian (a bound
    method: its parameters stay traced)."""

    energy: Callable
    mask: jax.Array  # (N, 1) 1.0 on the sites that move
    group: bool = eqx.field(static=True)
    n_sites: int = eqx.field(static=True)

    def __call__(self, state, t):
        s, restore = as_sites(state, self.n_sites)
        field = jax.grad(lambda y: jnp.sum(self.energy(y)))(s)
        return restore(turn(s, (t * jnp.asarray(self.mask, s.dtype)) * field))

    @property
    def is_group(self) -> bool:
        return self.group
