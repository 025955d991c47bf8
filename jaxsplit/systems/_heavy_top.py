"""The heavy top: a rigid body about a fixed point under gravity, state (m, Γ).

Γ is the upward vertical seen from the body (the unit vector against gravity) and χ the
centre of mass (from the fixed point, body frame), so with weight = M g >= 0 the potential is

    H(m, Γ) = Σ m_i²/(2I_i) + weight ⟨Γ, χ⟩,   the kick  m ← m + t weight (Γ × χ),

on se(3)* (``_potential``: structure, Casimirs |Γ|² and ⟨m, Γ⟩, the ``"axes"`` split of three
rotations and the kick, the two-piece ``"symmetric"`` split for I_1 = I_2). The Lagrange top
(I_1 = I_2, χ on axis 3) is the classic case; it spins steadily upright, the *sleeping top*
m = s χ/|χ|, Γ = χ/|χ|, which is linearly stable exactly when s² > 4 I_1 weight |χ| (the
"fast top"); hanging, Γ = −χ/|χ|, it is always stable.

Only weight·χ enters the equations: from (t, m, Γ) the product is determined, the factors
are not (``fit`` sees one null direction of the Gauss–Newton Hessian if both are free).
"""

import jax
import jax.numpy as jnp

from ._potential import BodyInPotential
from ._rigid_body import check_inertia, flag
from ._validate import check_batches, check_non_negative, check_vector


class HeavyTop(BodyInPotential):
    """A heavy top: principal moments ``inertia``, centre of mass ``center_of_mass`` (body
    frame), ``weight`` = M g >= 0 (zero: a free body carrying the vertical). Batched leading
    axes allowed (their batch shapes must broadcast, and a state needs the parameters' batch:
    one state is never integrated with several weights); every parameter is traced.
    ``allow_nonphysical`` as for ``RigidBody`` (a body violating the triangle inequalities).

    >>> import jax.numpy as jnp, jaxsplit
    >>> top = jaxsplit.heavy_top(jnp.array([2.0, 1.0, 2 / 3]), jnp.array([0.0, 0.0, 0.5]), 1.0,
    ...                          allow_nonphysical=True)                  # 1 + 2/3 < 2: on purpose
    >>> sorted(top.splits()), sorted(top.casimirs())
    (['axes', 'symmetric'], ['<m,Gamma>', '|Gamma|^2'])
    """

    inertia: jax.Array
    center_of_mass: jax.Array
    weight: jax.Array

    def __init__(self, inertia, center_of_mass, weight=1.0, allow_nonphysical: bool = False):
        self.inertia = check_inertia(inertia, allow_nonphysical=flag(allow_nonphysical))
        self.center_of_mass = check_vector(center_of_mass, "center_of_mass")
        self.weight = check_non_negative(weight, "weight")
        check_batches(inertia=self.inertia.shape[:-1], center_of_mass=self.center_of_mass.shape[:-1],
                      weight=self.weight.shape)

    def potential(self, gamma):
        """weight ⟨Γ, χ⟩: the height of the centre of mass times M g."""
        chi = jnp.asarray(self.center_of_mass, gamma.dtype)
        return jnp.asarray(self.weight, gamma.dtype) * jnp.sum(gamma * chi, axis=-1)

    def potential_bounds(self, gamma):
        moment = jnp.asarray(self.weight, gamma.dtype) * jnp.linalg.norm(
            jnp.asarray(self.center_of_mass, gamma.dtype), axis=-1)
        size = jnp.linalg.norm(gamma, axis=-1)
        return -moment * size, moment * size

    def equilibria(self, spin=1.0):
        """The sleeping top upright and hanging: m = spin·n, Γ = ±n, n = χ/|χ| (e_3 for χ = 0);
        equilibria when n is a principal axis (the Lagrange top) or ``spin`` = 0."""
        chi = jnp.asarray(self.center_of_mass)
        size = jnp.linalg.norm(chi)
        n = jnp.where(size > 0, chi / jnp.where(size > 0, size, 1.0), jnp.array([0.0, 0.0, 1.0], chi.dtype))
        return jnp.stack([spin * n, spin * n]), jnp.stack([n, -n])


def heavy_top(inertia, center_of_mass, weight=1.0, *, allow_nonphysical: bool = False) -> HeavyTop:
    """The heavy top, state (m, Γ): H = Σ m_i²/(2I_i) + weight ⟨Γ, χ⟩ (see ``HeavyTop``).

    >>> import jax.numpy as jnp, jaxsplit
    >>> top = jaxsplit.heavy_top(jnp.array([2.0, 1.0, 2 / 3]), jnp.array([0.0, 0.0, 0.5]), weight=1.0,
    ...                          allow_nonphysical=True)                  # 1 + 2/3 < 2: on purpose
    >>> x0 = (jnp.array([0.4, -0.3, 0.8]), jnp.array([0.0, 0.6, 0.8]))        # (m, Γ), |Γ| = 1
    >>> round(float(top.hamiltonian(x0)), 12)
    0.965
    >>> m, gamma = jaxsplit.integrate(jaxsplit.splitting(top, "strang"), x0, 0.01, 1000).final
    >>> abs(float(gamma @ gamma) - 1) < 1e-13, abs(float(m @ gamma - x0[0] @ x0[1])) < 1e-13   # Casimirs
    (True, True)
    """
    return HeavyTop(inertia, center_of_mass, weight, allow_nonphysical)
