"""The fast path of the bond split on a periodic hypercubic lattice (chain, square, simple
cubic; every length even): bond pairs by reshapes, spins components first inside the loop.

Where it applies (``pair_layout``): nearest-neighbour Heisenberg exchange with one coupling J
for every bond (no DM, no XXZ), the lattice's colours the (axis, parity) matchings that
``lattices._lattices`` builds: along ``axis``, sites 2k + parity and 2k + parity + 1 (mod L).
Anisotropy and field keep their site flows (they accept this layout too). Everywhere else
(any graph, per-bond couplings, DM, XXZ, odd or open lattices) the gather path of
``_spin_flows`` runs: the same maps, to round-off (``tests/test_spin_pairs.py``).

Layout. Inside a run the state is ``Components(x)``, x of shape (..., 3, L_1, ..., L_d):
each component a contiguous lattice. A colour along ``axis`` reshapes that axis to
(L/2, 2) (parity 1: after a roll by one site) and the two halves are the bonds' two ends:
no gather, no scatter. ``LaidOut`` (a ``Composition``) converts the user's (..., N, 3) or
(..., L_1, ..., L_d, 3) state once per call or run; a flow called alone on the user's layout
converts for itself (correct, slower).

The pair flow. For a bond H = −J S_i·S_j the sum s = S_i + S_j is conserved and both turn by
exp(−θ hat ŝ), θ = J t |s| (``_spin_flows``' convention, Ṡ_i = ∂H/∂S_i × S_i). With
w = (J t/2) s, φ = |w| = θ/2 and q = sin φ/φ:

    S_i' = S_i − 2 (A (s × S_i) − B s × (s × S_i)),  A = (J t/2) q cos φ,  B = (J t/2)² q²,
    S_j' = s − S_i'

(an increment, one rounding at the size of S_i; s kept to round-off). cos φ and q are even
functions of φ: polynomials in z = φ², without square root or division, on |φ| <= a bound.
The bound is known before the flow runs: |s| <= |S_i| + |S_j| and |S_i| = s_i (a Casimir,
``check_state``), so φ <= |J t| max_i s_i; a ``lax.switch`` takes the polynomial (``TIERS``,
economized as ``so3``'s kernel, to a quarter of the dtype's epsilon) where its range covers
twice that bound, or beyond it the full-range kernel (``so3.half_turn``: a square root, a
Cody–Waite reduction, a division). The switch is evaluated at run time: one program for every
h, J and spin length.

The native kernel. XLA's CPU emitter forms no multi-output fusion, so its kernel evaluated a
pair's sum, polynomials and cross products once per new component (six times a pair). On a CPU
with one device ``_pair_kernel.cc`` (``jaxsplit._native``: built on first use with the machine's
C++ compiler) runs the colour instead: one pass, in place, the same polynomials and tier test
(beyond the first tier the C library's cos and sin), within a few ulp of the XLA kernel
(``tests/test_native.py``). Sharded programs, other backends and other dtypes keep the XLA
kernel, as does any machine where it cannot be built (``jaxsplit._native.native_status()``).
"""

import dataclasses
import functools
from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _native
from ..core._compose import Composition
from ..core._flows import AbstractFlow
from .so3 import _economized, _horner, half_turn

# Bounds on φ = θ/2 of the polynomial tiers (beyond π/2: no reduction needed for cos and sin/φ in
# φ²); past the last, the full-range kernel. One tier: shorter polynomials for smaller bounds
# (1/16 and 1/2 had tiers of their own, 4 + 4 and 7 + 6 terms against 10 + 9) ran no faster
# (Strang on 32³ at h = 0.01: 18.2 against 18.4 M spin-steps/s median, the kernel alone 6.9, 6.3
# and 6.9 ns/spin/flow; the pass is bound by memory, not by the terms), and every tier is one
# more kernel per flow to compile (6.6 s for a 100-step Strang run on 8³ with four branches,
# 4.2 s with two: 2026-11-27).
TIERS = (2.0,)
SAFETY = 2.0  # the tier must cover twice the bound from the spin lengths (|S_i| up to 2 s_i)


class Components(eqx.Module):
    """A spin state components first: ``array`` (..., 3, L_1, ..., L_d)."""

    array: jax.Array


@functools.cache
def _coefficients(limit: float, dtype_name: str):
    tolerance = float(np.finfo(dtype_name).eps) / 4
    return _economized(0, Fraction(limit), tolerance), _economized(1, Fraction(limit), tolerance)


@dataclasses.dataclass(frozen=True)
class PairLayout:
    """The lattice shape (L_1, ..., L_d) and the conversions to and from ``Components``."""

    shape: tuple

    def _site_axes(self, shape) -> int:
        """1 for a (..., N, 3) state, d for (..., L_1, ..., L_d, 3)."""
        d = len(self.shape)
        return d if tuple(shape[len(shape) - 1 - d:-1]) == self.shape else 1

    def into(self, x) -> Components:
        x = jnp.asarray(x)
        d = len(self.shape)
        lead = x.shape[:x.ndim - 1 - self._site_axes(x.shape)]
        return Components(jnp.moveaxis(x.reshape(lead + self.shape + (3,)), -1, -1 - d))

    def out_of(self, c: Components, like):
        """``c`` in the layout of ``like`` (an array or a shape-and-dtype record)."""
        d = len(self.shape)
        y = jnp.moveaxis(c.array, -1 - d, -1)
        shape = tuple(like.shape)
        return y.reshape(y.shape[:-1 - d] + shape[len(shape) - 1 - self._site_axes(shape):])


def _cos_and_q(z, limit, dtype):
    """±(cos φ, q = sin φ/φ) from z = φ² (polynomials on |φ| <= ``limit``; ``limit`` None: the
    full-range kernel, whose one sign for both cancels in every product of the two)."""
    if limit is None:
        tiny = jnp.finfo(dtype).tiny
        inverse = jax.lax.rsqrt(z + tiny)
        c, s = half_turn((z + tiny) * inverse)
        return c, s * inverse
    cos_c, sin_c = _coefficients(limit, np.dtype(dtype).name)
    return _horner(cos_c, z), _horner(sin_c, z)


def _pair_coefficients(z, k, limit, dtype):
    """(A, B) = (k q cos φ, k² q²), q = sin φ/φ, from z = φ² (``_cos_and_q``)."""
    c, q = _cos_and_q(z, limit, dtype)
    return k * (q * c), (k * k) * (q * q)


class PairExchange(AbstractFlow):
    """Exact flow of −J Σ S_i·S_j over the colour (``axis``, ``parity``) of a periodic
    hypercubic lattice of shape ``shape`` (module docstring). ``coupling`` J (a scalar) and
    ``longest`` (the largest spin length) are traced."""

    coupling: jax.Array
    longest: jax.Array
    axis: int = eqx.field(static=True)
    parity: int = eqx.field(static=True)
    shape: tuple = eqx.field(static=True)

    def __call__(self, state, t):
        if not isinstance(state, Components):
            layout = PairLayout(self.shape)
            return layout.out_of(self(layout.into(state), t), state)
        x = state.array
        jt = jnp.asarray(self.coupling, x.dtype) * t
        bound = SAFETY * jnp.abs(jt) * jnp.asarray(self.longest, x.dtype)
        tier = sum((bound > limit).astype(jnp.int32) for limit in TIERS)
        # one kernel per flow: XLA evaluates the coefficients again for each of a pair's six new
        # components; computing them once in the switch and turning the ends after it (three
        # kernels more, 96 instead of 48 B/spin moved) measured no faster (spins-profile.md); again
        # on 2026-11-27 with (U, V) = (−2A, 2B) out of the switch: XLA's CPU fusion splits the turn
        # into several kernels and was ~3.5× slower. XLA's CPU pipeline forms no multi-output
        # fusions (six separate outputs gave nine kernels, the coefficients again per output),
        # and neither a concatenate (jnp.roll) nor a pad/select roll fuses into the kernel: parity 1
        # keeps its two roll passes (a pad/select roll along the last axis was 2× slower).
        return Components(_pair_flow(x, jt, tier, len(self.shape), self.axis, self.parity))


@functools.partial(jax.custom_jvp, nondiff_argnums=(3, 4, 5))
def _pair_flow(x, jt, tier, d, axis, parity):
    """The colour's flow: the native kernel (``_native``) where it runs, else the XLA kernel of
    tier ``tier`` (``TIERS``; past the last, the full range)."""
    if _native.pair_kernel_available(x.dtype) and len(TIERS) == 1:  # the kernel has one tier
        return _native_flow(x, jt, tier, d, axis, parity)
    return _xla_flow(x, jt, tier, d, axis, parity)


def _xla_flow(x, jt, tier, d, axis, parity):
    """The colour's flow by XLA: the kernel of tier ``tier`` under a ``lax.switch``."""
    branches = [functools.partial(_kernel, d=d, axis=axis, parity=parity, limit=limit) for limit in TIERS + (None,)]
    return jax.lax.switch(tier, branches, x, jt)


def _native_flow(x, jt, tier, d, axis, parity):
    """The colour's flow by ``_pair_kernel.cc``, in one pass and in place: the first tier's
    polynomials where ``tier`` is 0, else the C library's cos and sin."""
    cos_c, sin_c = (jnp.asarray(c, x.dtype) for c in _coefficients(TIERS[0], np.dtype(x.dtype).name))
    call = jax.ffi.ffi_call(_native.TARGET, jax.ShapeDtypeStruct(x.shape, x.dtype), vmap_method="broadcast_all",
                            input_output_aliases={0: 0})
    return call(x, jnp.asarray(jt, x.dtype), jnp.asarray(tier, jnp.int32), cos_c, sin_c, d=np.int64(d),
                axis=np.int64(axis), parity=np.int64(parity))


@_pair_flow.defjvp
def _pair_flow_jvp(d, axis, parity, primals, tangents):
    """The flow's derivative in closed form: differentiating the switch instead linearised every
    branch (the full-range kernel's reduction, square root and division included), which took most
    of a gradient's tracing and compilation (Strang on a chain of 8, reversible gradient of 6 steps:
    lower 3.9 s + compile 4.5 s). With a' = a − 2 (A u − B w), u = s × a, w = s × u, A = k Q1(z),
    B = k² Q2(z), z = k²|s|², k = J t / 2:
    da' = da − 2 (dA u + A du − dB w − B dw), db' = ds − da', dz = 2 k dk |s|² + 2 k² s·ds."""
    x, jt, tier = primals
    dx, djt, _ = tangents
    a, _, s, restore = _ends(x, d, axis, parity)
    da, _, ds, _ = _ends(dx, d, axis, parity)
    k, dk = 0.5 * jt, 0.5 * djt
    norm2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    z = (k * k) * norm2
    slopes = [functools.partial(_coefficients_and_slopes, limit=limit, dtype=x.dtype) for limit in TIERS + (None,)]
    q1, q2, q1z, q2z = jax.lax.switch(tier, slopes, z)
    A, B = k * q1, (k * k) * q2
    dz = 2 * k * dk * norm2 + 2 * (k * k) * (s[0] * ds[0] + s[1] * ds[1] + s[2] * ds[2])
    dA = dk * q1 + k * q1z * dz
    dB = 2 * k * dk * q2 + (k * k) * q2z * dz
    u = _cross(s, a)
    w = _cross(s, u)
    du = tuple(p + q for p, q in zip(_cross(ds, a), _cross(s, da), strict=True))
    dw = tuple(p + q for p, q in zip(_cross(ds, u), _cross(s, du), strict=True))
    new_da = tuple(da[i] - 2 * (dA * u[i] + A * du[i] - dB * w[i] - B * dw[i]) for i in range(3))
    new_db = tuple(ds[i] - new_da[i] for i in range(3))
    return _pair_flow(x, jt, tier, d, axis, parity), restore(new_da, new_db)


def _cross(p, q):
    return p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]


def _coefficients_and_slopes(z, limit, dtype):
    """(Q1, Q2, dQ1/dz, dQ2/dz) with Q1 = q cos φ, Q2 = q², q = sin φ/φ, z = φ² (``_pair_coefficients``
    without the factors of k): the derivatives of the polynomials on |φ| <= ``limit``, or (``limit``
    None, the full-range kernel) d cos φ/dz = −q/2 and dq/dz = (cos φ − q)/(2z)."""
    c, q = _cos_and_q(z, limit, dtype)
    if limit is None:
        c_z, q_z = -0.5 * q, (c - q) / (2 * (z + jnp.finfo(dtype).tiny))
    else:
        cos_c, sin_c = _coefficients(limit, np.dtype(dtype).name)
        c_z, q_z = (_horner(tuple(i * a for i, a in enumerate(cs))[1:], z) for cs in (cos_c, sin_c))
    return q * c, q * q, q_z * c + q * c_z, 2 * q * q_z


def _ends(x, d, axis, parity):
    """(a, b, s = a + b) as component lists of the bonds' two ends, and the function that puts
    the new ends back in x's layout."""
    ax = x.ndim - d + axis
    cax = x.ndim - d - 1
    if parity:
        x = jnp.roll(x, -1, ax)
    size = x.shape[ax]
    pairs = x.reshape(x.shape[:ax] + (size // 2, 2) + x.shape[ax + 1:])
    ends = [jnp.take(pairs, e, axis=ax + 1) for e in (0, 1)]
    a = [jnp.take(ends[0], i, axis=cax) for i in range(3)]
    b = [jnp.take(ends[1], i, axis=cax) for i in range(3)]
    s = (a[0] + b[0], a[1] + b[1], a[2] + b[2])

    def restore(first, second):
        out = jnp.stack([jnp.stack(first, axis=cax), jnp.stack(second, axis=cax)], axis=ax + 1).reshape(x.shape)
        return jnp.roll(out, 1, ax) if parity else out

    return a, b, s, restore


def _turned(a, s, A, B):
    """The pair's new ends: a' = a − 2 (A s × a − B s × (s × a)), b' = s − a'."""
    u = _cross(s, a)
    w = _cross(s, u)
    new = tuple(a[i] - 2 * (A * u[i] - B * w[i]) for i in range(3))
    return new, tuple(s[i] - new[i] for i in range(3))


def _kernel(x, jt, d, axis, parity, limit):
    """The flow of the colour (``axis``, ``parity``) for J t = ``jt`` on x (..., 3, L_1, ..., L_d),
    the coefficients from the polynomials on |φ| <= ``limit`` (None: full range), in one pass."""
    a, _, s, restore = _ends(x, d, axis, parity)
    k = 0.5 * jt
    A, B = _pair_coefficients((k * k) * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]), k, limit, x.dtype)
    return restore(*_turned(a, s, A, B))


class LaidOut(Composition):
    """A ``Composition`` whose flows run on ``Components``: the user's state converted once per
    call, run or backward pass (``layout``: a ``PairLayout``); the same map as the plain
    composition of the same flows."""

    layout: PairLayout | None = eqx.field(static=True, default=None)

    def __call__(self, state, h):
        if isinstance(state, Components):
            return super().__call__(state, h)
        return self.layout.out_of(super().__call__(self.layout.into(state), h), state)

    def advance(self, state, h, n, keep: bool = False):
        if isinstance(state, Components):
            return super().advance(state, h, n, keep)
        out = super().advance(self.layout.into(state), h, n, keep)
        if keep:
            y, kept = out
            return self.layout.out_of(y, state), self.layout.out_of(kept, kept_like(state, kept))
        return self.layout.out_of(out, state)

    def retrace(self, x_after, h, n, ct_after, kept=None):
        if isinstance(x_after, Components):
            return super().retrace(x_after, h, n, ct_after, kept)
        inner = None if kept is None else self.layout.into(kept)
        x, ct, ct_parameters, ct_h = super().retrace(self.layout.into(x_after), h, n, self.layout.into(ct_after), inner)
        return self.layout.out_of(x, x_after), self.layout.out_of(ct, ct_after), ct_parameters, ct_h


def kept_like(state, kept: Components):
    """A stand-in with the user's layout for a stack of kept states (one leading axis more)."""
    return jax.ShapeDtypeStruct((kept.array.shape[0],) + jnp.shape(state), kept.array.dtype)


def laid_out(step: Composition, layout: PairLayout) -> LaidOut:
    """``step`` run on ``layout``'s components (``LaidOut``)."""
    return LaidOut(step.flows, step.word, step.scheme, step.fsal, step.processing, layout)
