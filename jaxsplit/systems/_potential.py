"""A rigid body about a fixed point in a potential V(Γ) of one body-frame vector Γ: state (m, Γ).

H(m, Γ) = ½ Σ m_i²/I_i + V(Γ) on se(3)* with Π(m, Γ) = [[hat m, hat Γ], [hat Γ, 0]] over (m, Γ),
so ṁ = m × Wm + Γ × ∇V(Γ) and Γ̇ = Γ × Wm (Γ is a space-fixed direction seen from the body).
This Π is a Lie–Poisson structure (Jacobi identity exact); its Casimirs |Γ|² and ⟨m, Γ⟩ are
kept by every Poisson map. Subclasses give V (``potential``), validate their parameters and
name their equilibria: the heavy top (``_heavy_top``), the gravity-gradient satellite
(``_gravity_gradient``).

Pieces with exact flows:

* H_k = m_k²/(2I_k): m and Γ turn together about body axis k (``AxisRotation`` with parts
  ("momentum", "vector")), m_k invariant.
* V(Γ): Γ̇ = 0, so the torque Γ × ∇V(Γ) is constant along the flow and
  ``PotentialKick``: m ← m + t Γ × ∇V(Γ) is exact (∇V by ``jax.grad``, for any V).
* For a symmetric body (I_0 = I_1) the whole kinetic energy
  T = |m|²/(2I_0) + ½(1/I_2 − 1/I_0) m_2² is exact: a rotation about axis 2 and a spin of Γ
  about m (``MomentumSpin``), which commute.

Splits: ``"axes"`` (the three rotations and the kick: four pieces) and ``"symmetric"``
(I_0 = I_1: T and V, two pieces, so the partitioned (PRK) schemes apply too — the Lagrange top
and any top with I_0 = I_1). ``"casimir"`` is refused: |m|²/2 is no Casimir of se(3)*.
"""

from collections.abc import Callable
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._flows import AbstractKick
from ..core._state import fits_batch, host_values
from ._base import AbstractSystem
from ._rigid_body import is_concrete
from ._spin import Commuting, MomentumSpin
from ._validate import check_finite_state, check_unit
from .so3 import AxisRotation, check_shape, hat

PARTS = ("momentum", "vector")


class PotentialKick(AbstractKick):
    """Exact flow of a potential V(Γ) on the state (m, Γ): m ← m + t Γ × ∇V(Γ), Γ fixed (a kick:
    the reversible adjoint steps it back with one ``jax.vjp`` of the torque).

    ``potential`` is a function Γ -> V (a system's bound method: its parameters stay traced)."""

    potential: Callable

    def check_state(self, x):
        """The states of the system the potential belongs to (a bound method's owner)."""
        owner = getattr(self.potential, "__self__", None)
        # through the class: a bound method of an equinox module is a module built per lookup
        return type(owner).check_state(owner, x) if isinstance(owner, AbstractSystem) else x

    def velocity(self, state):
        """(the torque Γ × ∇V(Γ), None: Γ does not move)."""
        check_shape(state[0], "momentum")
        gamma = check_shape(state[1], "vector")
        # V has one value per state: a larger shape means a parameter batch (several weights,
        # rates, centres of mass) broadcast over one state, whose summed torque matches none
        # of them (shapes are static: checked under jit too)
        batch = jax.eval_shape(self.potential, gamma).shape
        if not fits_batch(batch, gamma.shape[:-1]):
            raise InputError(f"the potential's parameters have batch shape {tuple(batch)} but the state's batch "
                             f"shape is {tuple(gamma.shape[:-1])}: give one state per parameter set, shape "
                             f"{tuple(batch) + (3,)}, or vmap over the parameters")
        force = jax.grad(lambda g: jnp.sum(self.potential(g)))(gamma)
        return jnp.cross(gamma, force), None


class BodyInPotential(AbstractSystem):
    """A rigid body about a fixed point in a potential V(Γ) (see the module docstring)."""

    inertia: jax.Array
    refused_splits: ClassVar[dict[str, str]] = {
        "casimir": "|m|²/2 is no Casimir of (m, Γ) (the potential's torque changes |m|), so H − |m|²/(2I_k) "
                   "has another flow"}

    def potential(self, gamma):
        """V(Γ) (a scalar per state)."""
        raise NotImplementedError

    def potential_bounds(self, gamma):
        """(a lower bound of V on the sphere |Γ| = const, a bound on |∂(Γ × ∇V)/∂Γ|)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ structure
    def _parts(self, x):
        if not (isinstance(x, tuple) and len(x) == 2):
            raise InputError(f"the state of {self.name} is a tuple (m, Γ), got {type(x).__name__}")
        return check_shape(x[0], "momentum"), check_shape(x[1], "vector")

    def check_state(self, x):
        """``x`` as a state of this system, checked where concrete: a tuple (m, Γ) of finite
        (..., 3) arrays with Γ a unit vector (to √ε of its dtype; |Γ| is a Casimir, so a state
        from a long run passes). Returns ``x``."""
        _, gamma = BodyInPotential._parts(self, x)
        check_finite_state(x, f"the state of {type(self).__name__}")
        g = host_values(gamma)
        if g is not None:
            check_unit(np.sqrt(np.einsum("...i,...i->...", g, g)), "Γ must be a unit vector", "|Γ|", g.dtype)
        return x

    def kinetic_energy(self, x):
        m, _ = self._parts(x)
        return 0.5 * jnp.sum(m * m / jnp.asarray(self.inertia, m.dtype), axis=-1)

    def hamiltonian(self, x):
        return self.kinetic_energy(x) + self.potential(self._parts(x)[1])

    def poisson_matrix(self, x):
        m, gamma = self._parts(x)
        hg = hat(gamma)
        return jnp.block([[hat(m), hg], [hg, jnp.zeros((3, 3), m.dtype)]])

    def casimirs(self):
        return {"|Gamma|^2": lambda x: jnp.sum(x[1] * x[1], axis=-1),
                "<m,Gamma>": lambda x: jnp.sum(x[0] * x[1], axis=-1)}

    def max_rate(self, x0):
        """A bound on the pieces' frequencies along the motion: |m|² <= 2 I_max (H − min V) on the
        Casimir sphere |Γ| = |Γ_0| bounds the rotation rates |m_k|/I_k, and √(stiffness / I_min)
        the kick's linearised frequency."""
        m, gamma = self._parts(x0)
        w = 1 / jnp.asarray(self.inertia, m.dtype)
        v_min, stiffness = self.potential_bounds(gamma)
        kinetic = jnp.maximum(self.hamiltonian(x0) - v_min, 0.0)
        m_max = jnp.sqrt(2 * kinetic / jnp.min(w, axis=-1))
        return jnp.maximum(m_max * jnp.max(w, axis=-1), jnp.sqrt(stiffness * jnp.max(w, axis=-1)))

    # ------------------------------------------------------------------ splits
    def splits(self):
        return {"axes": self.axes_split, "symmetric": self.symmetric_split}

    def kick(self) -> PotentialKick:
        return PotentialKick(self.potential)

    def axes_split(self) -> tuple:
        """Three rotations of (m, Γ), H_k = m_k²/(2I_k), and the potential kick."""
        w = 1 / self.inertia
        return tuple(AxisRotation(k, w[..., k], PARTS) for k in range(3)) + (self.kick(),)

    def symmetric_split(self) -> tuple:
        """Two pieces for I_0 = I_1: the exact kinetic flow (rotation about axis 2 and spin about
        m) and the potential kick."""
        if is_concrete(self.inertia):
            i = host_values(self.inertia, whole=True)  # it decides the split: the same everywhere
            if not np.allclose(i[..., 0], i[..., 1], rtol=1e-12, atol=0):
                raise InputError(f"split 'symmetric' needs I1 = I2 (the kinetic flow is exact only for a symmetric "
                                 f"body, axis 3 its symmetry axis), got inertia {i.tolist()}")
        w = 1 / self.inertia
        kinetic = Commuting((AxisRotation(2, w[..., 2] - w[..., 0], PARTS), MomentumSpin(w[..., 0], PARTS)))
        return kinetic, self.kick()
