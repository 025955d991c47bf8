"""Rotations by an angle vector that may vanish, and the flow that spins a state about m.

``exp_hat(a)`` = exp(hat(a)) (Rodrigues) and ``turn(v, a)`` = exp(−hat(a)) v are written with
sin|a|/|a| and (1 − cos|a|)/|a|² evaluated by their Taylor series near a = 0, so values and
derivatives are finite everywhere (a steady rotation with ω = 0, a top with m = 0), and
applied as increments so that repeated turns keep norms without a rounding bias.

``MomentumSpin(rate, parts)`` is the exact flow of ½ c |m|² on a state whose parts are declared
as in ``so3``: m is fixed (m × ∇ = c m × m = 0) and every other part turns by
exp(−c t hat(m)), i.e. about m by the angle c|m|t: vectors v ← exp(−ct hat(m)) v, an attitude
Q ← Q exp(ct hat(m)), a quaternion q ← q ⊗ (cos(c|m|t/2), sin(c|m|t/2) m/|m|). On so(3)* alone
½|m|² is the Casimir and the flow is the identity; on the larger structures (attitude, heavy
top) it is not, but it still commutes with every function of m, which is what lets the
attitude and the symmetric top keep a two-piece split (see ``_attitude``, ``_heavy_top``).

``Commuting(flows)`` is the exact flow of a sum of Poisson-commuting pieces (the flows applied
in turn): one piece of a split made of several exactly solvable commuting parts.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._flows import AbstractFlow
from .so3 import check_parts, check_shape, cos_sin, momentum, quaternion_multiply

_SMALL = 1e-4  # below this |a| the Taylor series (to a⁴) are exact to round-off in float64


def _half_sinc_cos(a):
    """(sin(|a|/2)/(|a|/2), cos(|a|/2)) with |a|² = a·a, smooth at a = 0 (one ``cos_sin`` of |a|/2)."""
    sq = jnp.sum(a * a, axis=-1)
    small = sq < _SMALL**2
    half = 0.5 * jnp.sqrt(jnp.where(small, 1.0, sq))
    cos_half, sin_half = cos_sin(half)
    return (jnp.where(small, 1 - sq / 24 + sq * sq / 1920, sin_half / half),
            jnp.where(small, 1 - sq / 8 + sq * sq / 384, cos_half))


def turn(v, a):
    """exp(−hat(a)) v = v − (a × v) sin|a|/|a| + a × (a × v)(1 − cos|a|)/|a|², applied from the half
    angle as an increment (as in ``so3.half_cos_sin``: norms kept without a rounding bias):
    v − σ (cos(|a|/2) a × v − ½σ a × (a × v)), σ = sin(|a|/2)/(|a|/2)."""
    sinc, cos = (x[..., None] for x in _half_sinc_cos(a))
    av = jnp.cross(a, v)
    return v - sinc * (cos * av - 0.5 * sinc * jnp.cross(a, av))


def exp_hat(a):
    """exp(hat(a)) as a matrix, shape a.shape[:-1] + (3, 3)."""
    eye = jnp.broadcast_to(jnp.eye(3, dtype=a.dtype), a.shape[:-1] + (3, 3))
    # column j of exp(hat(a)) = exp(hat(a)) e_j = turn(e_j, −a)
    return jnp.swapaxes(turn(eye, -a[..., None, :]), -1, -2)


def half_turn_increment(a):
    """r − 1 for r = (cos(|a|/2), sin(|a|/2) a/|a|), the quaternion of exp(hat(a)), from the quarter
    angle: σ (−½σ |a/2|², cos(|a|/4) a/2) with σ = sin(|a|/4)/(|a|/4); q ⊗ r = q + q ⊗ (r − 1)."""
    half = a / 2
    sinc, cos = _half_sinc_cos(half)
    scalar = -0.5 * sinc * jnp.sum(half * half, axis=-1)
    return sinc[..., None] * jnp.concatenate([scalar[..., None], cos[..., None] * half], axis=-1)


class MomentumSpin(AbstractFlow):
    """Exact flow of H = ½ c |m|²: m fixed, every other declared part turned about m by c|m|t
    (see the module docstring). ``rate`` = c is traced; ``parts`` is static."""

    rate: jax.Array = eqx.field(converter=jnp.asarray)
    parts: tuple | None = eqx.field(static=True, default=None, converter=check_parts)

    def check_state(self, x):
        if self.parts is None or "attitude" not in self.parts and "quaternion" not in self.parts:
            return x  # momenta and body vectors: any vector
        from ._validate import check_parts as check_values  # _validate builds on so3

        return check_values(x, self.parts)

    def __call__(self, state, t):
        m = momentum(state, self.parts)
        if self.parts is None:  # on so(3)* alone the flow is the identity
            return state
        a = self.rate.astype(m.dtype) * t * m
        out = []
        for part, leaf in zip(self.parts, state):
            check_shape(leaf, part)
            if part == "vector":
                out.append(turn(leaf, a))
            elif part == "attitude":  # rows of Q turn like body vectors: Q exp(hat a)
                out.append(turn(leaf, a[..., None, :]))
            elif part == "quaternion":
                out.append(leaf + quaternion_multiply(leaf, half_turn_increment(a)))
            else:  # m itself (exactly fixed) and "fixed" parts
                out.append(leaf)
        return type(state)(*out) if hasattr(state, "_fields") else tuple(out)


class Commuting(AbstractFlow):
    """The exact flow of a sum of Poisson-commuting pieces: their flows applied one after the
    other (any order). A one-parameter group when every piece is one."""

    flows: tuple

    def __call__(self, state, t):
        for flow in self.flows:
            state = flow(state, t)
        return state

    @property
    def is_group(self) -> bool:
        return all(f.is_group for f in self.flows)
