"""Splittings of the free rigid body into exactly solvable rotations.

``split="axes"`` (the seed paper): H = H_1 + H_2 + H_3 with H_i = m_i²/(2 I_i), three
rotations about the body axes, each angle θ_i = m_i t / I_i taken from the state the
piece acts on.

``split="casimir"``: C = |m|²/2 Poisson-commutes with everything, so H − C/I_k has the same
flow as H and is a sum of TWO rotation generators Σ_{i≠k} ½ (1/I_i − 1/I_k) m_i². The
shift axis k is the user's choice or, with ``shift_axis="auto"``, the axis with the middle
value of 1/I: it minimises |c_a c_b|, the size of the leading commutator [H_a, H_b] of the
two pieces, and for a symmetric body (I1 = I2) it removes one piece altogether, making
every scheme exact.
"""

import dataclasses

import jax
import numpy as np

from ._body import RigidBody
from ._compose import Composition, compose
from ._errors import InputError
from ._rotations import rotate

SPLITS = ("axes", "casimir")


@dataclasses.dataclass(frozen=True)
class AxisRotation:
    """Exact flow of ½ (1/I_axis − 1/I_shift) m_axis²: a rotation about body ``axis``.

    ``flow(m, t, body)``; with ``shift=None`` it is the paper's H_axis (M, N or P).
    """

    axis: int
    shift: int | None = None

    def rate(self, body: RigidBody, dtype):
        inverse = 1 / body.inertia.astype(dtype)
        return inverse[self.axis] - (0 if self.shift is None else inverse[self.shift])

    def __call__(self, m, t, body: RigidBody):
        angle = self.rate(body, m.dtype) * m[self.axis] * t
        return rotate(m, self.axis, angle)


def auto_shift_axis(body: RigidBody) -> int:
    """The axis (0-based) whose 1/I_k is the middle value; needs concrete inertia."""
    inertia = body.inertia
    if isinstance(inertia, jax.core.Tracer):
        raise InputError(
            "shift_axis='auto' needs concrete inertia; inside jit/vmap/grad pass shift_axis=1, 2 or 3"
        )
    inertia = np.asarray(inertia)
    if inertia.ndim != 1:
        raise InputError("shift_axis='auto' needs a single body; vmap with an explicit shift_axis")
    return int(np.argsort(1 / inertia, kind="stable")[1])


def rigid_body_flows(body: RigidBody, split: str = "axes", shift_axis="auto") -> tuple:
    """The exact sub-flows of ``body`` for ``split`` (see the module docstring)."""
    if split == "axes":
        return tuple(AxisRotation(k) for k in range(3))
    if split == "casimir":
        if shift_axis == "auto":
            k = auto_shift_axis(body)
        elif shift_axis in (1, 2, 3):
            k = shift_axis - 1
        else:
            raise InputError(f"shift_axis must be 1, 2, 3 or 'auto', got {shift_axis!r}")
        return tuple(AxisRotation(i, k) for i in range(3) if i != k)
    raise InputError(f"split must be one of {SPLITS}, got {split!r}")


def splitting(body: RigidBody, scheme, split: str = "axes", *, shift_axis="auto",
              merge_flows: bool = True) -> Composition:
    """One step ``step(m, h)`` of ``scheme`` applied to the exact rotations of ``body``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> step = jaxsplit.splitting(jaxsplit.RigidBody([2.0, 2.0, 1.0]), "strang")
    >>> m1 = step(jnp.array([0.6, 0.0, 0.8]), 0.1)
    """
    if not isinstance(body, RigidBody):
        body = RigidBody(body)
    return compose(rigid_body_flows(body, split, shift_axis), scheme, body, merge_flows=merge_flows)
