"""Two integrators the spin-dynamics field uses, for any spin Hamiltonian: baselines to audit
against the exact splittings (``jaxsplit spins-audit``).

* ``spherical_midpoint`` (McLachlan, Modin, Verdier, Phys. Rev. E 89 (2014) 061301; Sunny.jl's
  ``ImplicitMidpoint``): S_i' = S_i + h ∂H/∂S_i(S̄) × S̄_i with S̄_i = s_i (S_i + S_i')/|S_i + S_i'|,
  symplectic on the product of spheres, second order, |S_i| exact (S_i' − S_i ⟂ S_i + S_i').
  Implicit: fixed-point iterations until the update stops changing (round-off) or
  ``max_iter``; ``jacfwd`` differentiates through the iterations.
* ``heun``: the explicit trapezoid (Heun) step of Ṡ_i = ∂H/∂S_i × S_i followed by scaling
  each spin back to its length (VAMPIRE, UppASD): second order, not a Poisson map.

Both act on a ``SpinLattice`` state ((N, 3) or the lattice's shape + (3,)) and use its
``local_field`` ∂H/∂S_i.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._errors import InputError
from ..core._flows import AbstractFlow


def _check(system):
    if not hasattr(system, "local_field") or not hasattr(system, "spin_length"):
        raise InputError(f"this integrator acts on a spin system (jaxsplit.spin_lattice), got {type(system).__name__}")
    return system


class SphericalMidpoint(AbstractFlow):
    """The spherical midpoint step (module docstring); ``max_iter`` fixed-point iterations at most."""

    system: eqx.Module
    max_iter: int = eqx.field(static=True, default=100)

    def __call__(self, state, h):
        s = self.system.sites(state)
        h = jnp.asarray(h, s.dtype)
        lengths = jnp.asarray(self.system.spin_length, s.dtype)[..., None]
        tol = 4 * jnp.finfo(s.dtype).eps * jnp.max(jnp.abs(s))

        def update(new):
            mid = s + new
            mid = lengths * mid / jnp.linalg.norm(mid, axis=-1, keepdims=True)
            return s + h * jnp.cross(self.system.local_field(mid), mid)

        def body(carry):
            new, _, k = carry
            nxt = update(new)
            return nxt, jnp.max(jnp.abs(nxt - new)), k + 1

        def going(carry):
            _, change, k = carry
            return (change > tol) & (k < self.max_iter)

        first = update(s)
        new, _, _ = jax.lax.while_loop(going, body, (first, jnp.asarray(jnp.inf, s.dtype), jnp.asarray(1)))
        for _ in range(2):  # the tangents (jacfwd) converge one contraction behind the values
            new = update(new)
        return new.reshape(jnp.shape(state))

    @property
    def is_group(self) -> bool:
        return False


class Heun(AbstractFlow):
    """Heun's step with each spin scaled back to its length (module docstring)."""

    system: eqx.Module

    def __call__(self, state, h):
        s = self.system.sites(state)
        h = jnp.asarray(h, s.dtype)
        lengths = jnp.asarray(self.system.spin_length, s.dtype)[..., None]

        def rate(y):
            return jnp.cross(self.system.local_field(y), y)

        k1 = rate(s)
        k2 = rate(s + h * k1)
        new = s + (h / 2) * (k1 + k2)
        return (lengths * new / jnp.linalg.norm(new, axis=-1, keepdims=True)).reshape(jnp.shape(state))

    @property
    def is_group(self) -> bool:
        return False


def spherical_midpoint(system, max_iter: int = 100) -> SphericalMidpoint:
    """The spherical midpoint step of a spin system (``SphericalMidpoint``): a step(x, h).

    >>> import jax.numpy as jnp, jaxsplit
    >>> system = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 6), exchange=1.0)
    >>> s0 = system.random_state(seed=1)
    >>> s1 = jaxsplit.integrate(jaxsplit.spherical_midpoint(system), s0, 0.1, 50).final
    >>> bool(jnp.max(jnp.abs(jnp.linalg.norm(s1, axis=-1) - 1)) < 1e-13)
    True
    """
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise InputError(f"max_iter must be an integer >= 1, got {max_iter!r}")
    return SphericalMidpoint(_check(system), max_iter)


def heun(system) -> Heun:
    """Heun's method with renormalisation for a spin system (``Heun``): a step(x, h).

    >>> import jax.numpy as jnp, jaxsplit
    >>> system = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 6), exchange=1.0)
    >>> jaxsplit.heun(system)(system.random_state(seed=1), 0.1).shape
    (6, 3)
    """
    return Heun(_check(system))
