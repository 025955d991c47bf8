"""A satellite in the gravity-gradient field of a planet: state (m, Γ), Γ the unit vector to
the planet seen from the body.

On a circular orbit of rate Ω (Ω² = μ/R³) the tidal potential of the planet across the body
is, up to a constant, V(Γ) = (3/2) Ω² ⟨Γ, IΓ⟩, whose torque Γ × ∇V = 3 Ω² Γ × IΓ is the
classical gravity-gradient torque. Here Γ moves only with the body (Γ̇ = Γ × Wm): the
direction to the planet is held fixed in inertial space, the model of a body whose attitude
motion is fast against the orbit (Brun's problem, a rigid body in a quadratic potential on
se(3)*). The turning of the orbital frame itself (at Ω about the orbit normal) is not part of
this model. The kick m ← m + 3 t Ω² Γ × IΓ is exact because Γ is fixed in it; the rest
(structure, Casimirs, splits) is ``_potential``'s.

Equilibria: a principal axis pointing at the planet, Γ = e_k, spinning about it at any rate,
m = s e_k; static (s = 0) the attitude with the smallest moment towards the planet is the
minimum of V (stable), the largest its maximum and the middle one a saddle, and a fast spin
stabilises the maximum gyroscopically.
"""

import jax
import jax.numpy as jnp

from ._potential import BodyInPotential
from ._rigid_body import check_inertia, flag
from ._validate import check_batches, check_non_negative


class GravityGradient(BodyInPotential):
    """A rigid satellite (principal moments ``inertia``) in the gravity gradient of a planet,
    orbital rate ``rate`` = Ω >= 0. Batched leading axes allowed (as for ``HeavyTop``); every
    parameter is traced. ``allow_nonphysical`` as for ``RigidBody``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> satellite = jaxsplit.gravity_gradient(jnp.array([2.0, 1.0, 2 / 3]), 0.1, allow_nonphysical=True)
    >>> sorted(satellite.splits())
    ['axes', 'symmetric']
    """

    inertia: jax.Array
    rate: jax.Array

    def __init__(self, inertia, rate, allow_nonphysical: bool = False):
        self.inertia = check_inertia(inertia, allow_nonphysical=flag(allow_nonphysical))
        self.rate = check_non_negative(rate, "rate")
        check_batches(inertia=self.inertia.shape[:-1], rate=self.rate.shape)

    def potential(self, gamma):
        """(3/2) Ω² ⟨Γ, IΓ⟩."""
        inertia = jnp.asarray(self.inertia, gamma.dtype)
        rate = jnp.asarray(self.rate, gamma.dtype)
        return 1.5 * rate**2 * jnp.sum(gamma * inertia * gamma, axis=-1)

    def potential_bounds(self, gamma):
        inertia = jnp.asarray(self.inertia, gamma.dtype)
        scale = 3 * jnp.asarray(self.rate, gamma.dtype) ** 2 * jnp.sum(gamma * gamma, axis=-1)
        return 0.5 * scale * jnp.min(inertia, axis=-1), scale * jnp.max(inertia, axis=-1)

    def equilibria(self, spin=0.0):
        """A principal axis towards the planet, Γ = e_k, spinning at ``spin`` about it: m = spin·e_k."""
        eye = jnp.eye(3, dtype=jnp.result_type(self.inertia))
        return spin * eye, eye


def gravity_gradient(inertia, rate, *, allow_nonphysical: bool = False) -> GravityGradient:
    """A satellite in the gravity-gradient field, state (m, Γ): V = (3/2) rate² ⟨Γ, IΓ⟩.

    >>> import jax.numpy as jnp, jaxsplit
    >>> satellite = jaxsplit.gravity_gradient(jnp.array([2.0, 1.0, 2 / 3]), rate=0.1, allow_nonphysical=True)
    >>> x0 = (jnp.zeros(3), jnp.array([0.0, 0.6, 0.8]))            # at rest in the body, Γ toward the planet
    >>> m, gamma = jaxsplit.integrate(jaxsplit.splitting(satellite, "strang"), x0, 0.1, 500).final
    >>> abs(float(gamma @ gamma) - 1) < 1e-13
    True
    """
    return GravityGradient(inertia, rate, allow_nonphysical)
