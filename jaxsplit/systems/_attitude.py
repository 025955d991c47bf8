"""The free rigid body with its attitude: state (m, Q), Q ∈ SO(3) body to space, or (m, q)
with q a unit quaternion (w, x, y, z).

ṁ = m × Wm, Q̇ = Q hat(Wm) (W = diag(1/I)): each row of Q turns like a body vector, so with the
rows q_0, q_1, q_2 of Q the structure is the Lie–Poisson structure of so(3) ⋉ (R³)³,

    Π(m, Q) = [[hat m, hat q_0, hat q_1, hat q_2], [hat q_0, 0, 0, 0], [hat q_1, 0…], [hat q_2, 0…]]

over (m, Q raveled row by row) — the heavy top's se(3)* structure with three vectors, a Poisson
structure whatever the potential (so ``jacobi_defect`` vanishes identically). Its Casimirs are
the inner products of the rows, Q Qᵀ (= 1 on SO(3)); the energy, |m|² and the spatial angular
momentum L = Q m are first integrals of this Hamiltonian. For a quaternion, q̇ = ½ q ⊗ (0, ω) = B(q) ω
with B(q) = ½ [−q_vᵀ; q_w 1 + hat(q_v)], and Π(m, q) = [[hat m, −B(q)ᵀ], [B(q), 0]] (the
Lie–Poisson structure of so(3) ⋉ R⁴ for the spin representation; Casimir |q|²).

Splits (each piece's flow exact, turning m and the attitude together, ``so3``):

* ``"axes"``: the three rotations H_k = m_k²/(2I_k), each turning m and Q (Q ← Q R_kᵀ).
* ``"spin"``: two pieces. H = Σ_{i≠k} ½(1/I_i − 1/I_k) m_i² + |m|²/(2I_k); the last term is no
  Casimir here (it turns Q about m), but it Poisson-commutes with every function of m, so its
  exact flow (``MomentumSpin``: Q ← Q exp(t hat(m)/I_k), m fixed) is carried by the first
  rotation piece. The m-motion is the free body's ``"casimir"`` split; partitioned (PRK)
  schemes apply. ``shift`` = k (0-based) or ``"auto"`` (the middle 1/I, as for ``RigidBody``).
* ``"casimir"`` is refused: H − |m|²/(2I_k) has the same m-flow but turns Q at the wrong rate.
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._errors import InputError
from ._base import AbstractSystem
from ._rigid_body import check_inertia, flag, shift_axis
from ._spin import Commuting, MomentumSpin
from ._validate import check_attitude, check_finite_state
from .so3 import AxisRotation, check_shape, hat, quaternion_to_matrix


def _quaternion_map(q):
    """B(q) (4, 3): q̇ = ½ q ⊗ (0, ω) = B(q) ω."""
    w, v = q[0], q[1:]
    return 0.5 * jnp.concatenate([-v[None, :], w * jnp.eye(3, dtype=q.dtype) + hat(v)], axis=0)


class Attitude(AbstractSystem):
    """The free rigid body with its attitude: state (m, Q) with Q (3, 3), or (m, q) with a unit
    quaternion q (4,) when ``quaternion=True`` (see the module docstring).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.attitude(jnp.array([2.0, 1.0, 2 / 3]), allow_nonphysical=True)   # 1 + 2/3 < 2
    >>> sorted(body.splits()), sorted(body.invariants())
    (['axes', 'spin'], ['Q Q^T', 'Q m', 'Q^T Q', 'energy', '|m|^2'])
    """

    inertia: jax.Array
    quaternion: bool = eqx.field(static=True, default=False)
    refused_splits: ClassVar[dict[str, str]] = {
        "casimir": "|m|²/2 is no Casimir of (m, attitude): H − |m|²/(2I_k) turns the attitude at the wrong rate; "
                   "split 'spin' carries that term as an exact spin about m"}

    def __init__(self, inertia, quaternion: bool = False, allow_nonphysical: bool = False):
        self.inertia = check_inertia(inertia, allow_nonphysical=flag(allow_nonphysical))
        if not isinstance(quaternion, bool):
            raise InputError(f"quaternion must be True or False, got {quaternion!r}")
        self.quaternion = quaternion

    @property
    def part(self) -> str:
        return "quaternion" if self.quaternion else "attitude"

    def _split_state(self, x):
        if not (isinstance(x, tuple) and len(x) == 2):
            raise InputError(f"the attitude state is a tuple (m, {'q' if self.quaternion else 'Q'}), got "
                             f"{type(x).__name__}")
        return check_shape(x[0], "momentum"), check_shape(x[1], self.part)

    def check_state(self, x):
        """``x`` as a state of this system, checked where concrete: (m, Q) finite with Q ∈ SO(3)
        (QᵀQ = 1 and det Q = 1 to √ε of its dtype), or (m, q) with |q| = 1. Returns ``x``."""
        _, a = self._split_state(x)
        check_finite_state(x, "the attitude state")
        check_attitude(a, self.quaternion)
        return x

    def rotation(self, x):
        """Q: the attitude as a rotation matrix (from the quaternion when ``quaternion``)."""
        _, a = self._split_state(x)
        return quaternion_to_matrix(a) if self.quaternion else a

    # ------------------------------------------------------------------ structure
    def hamiltonian(self, x):
        m, _ = self._split_state(x)
        return 0.5 * jnp.sum(m * m / jnp.asarray(self.inertia, m.dtype), axis=-1)

    def poisson_matrix(self, x):
        m, a = self._split_state(x)
        if self.quaternion:
            b = _quaternion_map(a)
            return jnp.block([[hat(m), -b.T], [b, jnp.zeros((4, 4), m.dtype)]])
        rows = [hat(a[i]) for i in range(3)]
        zero = jnp.zeros((3, 3), m.dtype)
        return jnp.block([[hat(m), *rows]] + [[r] + [zero] * 3 for r in rows])

    def casimirs(self):
        if self.quaternion:
            return {"|q|^2": lambda x: jnp.sum(x[1] * x[1], axis=-1)}
        return {"Q Q^T": lambda x: x[1] @ jnp.swapaxes(x[1], -1, -2)}

    def invariants(self):
        return {"energy": self.hamiltonian, **self.casimirs(),
                "|m|^2": lambda x: jnp.sum(x[0] * x[0], axis=-1),
                "Q m": lambda x: jnp.einsum("...ij,...j->...i", self.rotation(x), x[0]),
                "Q^T Q": lambda x: jnp.swapaxes(self.rotation(x), -1, -2) @ self.rotation(x)}

    def max_rate(self, x0):
        """|m| is conserved and the attitude turns at |Wm| <= |m| max(1/I): a bound on every
        piece's rate (rotations (1/I_i − 1/I_k) m_i and the spin |m|/I_k alike)."""
        m = x0[0]
        return jnp.linalg.norm(m, axis=-1) * jnp.max(1 / jnp.asarray(self.inertia, m.dtype), axis=-1)

    def equilibria(self):
        """Steady rotations about the principal axes, |m| = 1, from the identity attitude."""
        dtype = jnp.result_type(self.inertia)
        eye = jnp.eye(3, dtype=dtype)
        if self.quaternion:
            return eye, jnp.broadcast_to(jnp.eye(4, dtype=dtype)[0], (3, 4))
        return eye, jnp.broadcast_to(eye, (3, 3, 3))

    @property
    def reference_split(self) -> tuple[str, dict]:
        return "spin", {"shift": 1}

    # ------------------------------------------------------------------ splits
    def splits(self):
        return {"axes": self.axes_split, "spin": self.spin_split}

    def axes_split(self) -> tuple:
        """Three rotations of (m, attitude), H_k = m_k²/(2I_k)."""
        w = 1 / self.inertia
        return tuple(AxisRotation(k, w[..., k], ("momentum", self.part)) for k in range(3))

    def spin_split(self, shift="auto") -> tuple:
        """Two pieces: the rotation about axis a with the spin |m|²/(2I_k), and the rotation about b."""
        k = shift_axis(self.inertia, shift)
        w = 1 / self.inertia
        parts = ("momentum", self.part)
        a, b = (i for i in range(3) if i != k)
        return (Commuting((AxisRotation(a, w[..., a] - w[..., k], parts), MomentumSpin(w[..., k], parts))),
                AxisRotation(b, w[..., b] - w[..., k], parts))

    def resolve_split(self, name=None, **options):
        name, options = super().resolve_split(name, **options)
        if name == "spin":
            options["shift"] = shift_axis(self.inertia, options.get("shift", "auto"))
        return name, options


def attitude(inertia, quaternion: bool = False, *, allow_nonphysical: bool = False) -> Attitude:
    """The free rigid body with its attitude, state (m, Q) (or (m, q), ``quaternion=True``):
    splits ``"axes"`` (three rotations) and ``"spin"`` (two pieces: every scheme applies).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.attitude(jnp.array([2.0, 1.0, 2 / 3]), allow_nonphysical=True)   # 1 + 2/3 < 2
    >>> x0 = (jnp.array([0.4, -0.3, 0.8]), jnp.eye(3))
    >>> m, Q = jaxsplit.integrate(jaxsplit.splitting(body, "strang"), x0, 0.05, 200).final
    >>> float(jnp.max(jnp.abs(Q @ m - x0[0]))) < 1e-13, float(jnp.max(jnp.abs(Q.T @ Q - jnp.eye(3)))) < 1e-13
    (True, True)
    """
    return Attitude(inertia, quaternion, allow_nonphysical)
