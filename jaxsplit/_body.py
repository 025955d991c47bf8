"""The free rigid body as a Lie–Poisson system on so(3)* = R³.

H(m) = ½ Σ m_i²/I_i,  C(m) = ½|m|²,  Π(m) = hat(m),  ṁ = Π(m) ∇H(m) = m × I⁻¹m
(the seed paper's sign convention). The inertia is an array leaf of a PyTree, so
``jax.vmap`` sweeps bodies and ``jax.grad`` differentiates through it; concrete values
are validated when a body is built.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import InputError
from ._rotations import hat


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _as_float_array(x, name: str):
    """An array of a floating dtype: integers are promoted, floats keep their dtype."""
    if isinstance(x, (jax.Array, np.ndarray)) and jnp.issubdtype(x.dtype, jnp.floating):
        return jnp.asarray(x)
    try:
        arr = jnp.asarray(x)
    except (TypeError, ValueError) as err:
        raise InputError(f"{name} must be numeric, got {x!r}") from err
    if not jnp.issubdtype(arr.dtype, jnp.floating):
        if not (jnp.issubdtype(arr.dtype, jnp.integer) or arr.dtype == bool):
            raise InputError(f"{name} must be real numbers, got dtype {arr.dtype}")
        arr = arr.astype(jnp.result_type(float))
    return arr


@jax.tree_util.register_pytree_node_class
class RigidBody:
    """A free rigid body with principal moments of inertia ``inertia = (I1, I2, I3) > 0``.

    ``inertia`` may carry leading batch axes (shape ``(..., 3)``); the methods act on a
    single state ``m`` of shape ``(3,)`` and are meant to be vmapped.
    """

    __slots__ = ("inertia",)

    def __init__(self, inertia):
        inertia = _as_float_array(inertia, "inertia")
        if _is_concrete(inertia):
            if inertia.ndim < 1 or inertia.shape[-1] != 3:
                raise InputError(
                    f"inertia must have 3 components (I1, I2, I3), got shape {tuple(inertia.shape)}"
                )
            values = np.asarray(inertia)
            if not np.all(np.isfinite(values)):
                raise InputError(f"inertia must be finite, got {values.tolist()}")
            if not np.all(values > 0):
                raise InputError(f"inertia must be positive, got {values.tolist()}")
        object.__setattr__(self, "inertia", inertia)

    def __setattr__(self, name, value):
        raise AttributeError("RigidBody is immutable")

    def tree_flatten(self):
        return (self.inertia,), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        # Rebuilt inside transformations with tracers or placeholders: no validation.
        body = object.__new__(cls)
        object.__setattr__(body, "inertia", children[0])
        return body

    def __repr__(self):
        return f"RigidBody(inertia={self.inertia!r})"

    def _inverse_inertia(self, m):
        # Computation follows the state's dtype (float32 in -> float32 out).
        return 1 / jnp.asarray(self.inertia, dtype=jnp.result_type(m))

    def hamiltonian(self, m):
        """Kinetic energy H(m) = ½ Σ m_i² / I_i."""
        return 0.5 * jnp.sum(m * m * self._inverse_inertia(m), axis=-1)

    def casimir(self, m):
        """C(m) = ½ |m|², conserved by every Poisson map of so(3)*."""
        return 0.5 * jnp.sum(m * m, axis=-1)

    def poisson_matrix(self, m):
        """Π(m) = hat(m), the Lie–Poisson structure of so(3)*."""
        return hat(m)

    def vector_field(self, m):
        """ṁ = Π(m) ∇H(m) = m × (I⁻¹ m)."""
        return jnp.cross(m, m * self._inverse_inertia(m))

    def is_physical(self) -> bool:
        """Triangle inequalities I_i + I_j >= I_k (concrete inertia only)."""
        i1, i2, i3 = np.moveaxis(np.asarray(self.inertia), -1, 0)
        return bool(np.all((i1 + i2 >= i3) & (i2 + i3 >= i1) & (i3 + i1 >= i2)))


class StandardCase(NamedTuple):
    """The asymmetric test case of Hairer–Lubich–Wanner (GNI) with a 30-digit reference."""

    inertia: tuple = (2.0, 1.0, 2.0 / 3.0)
    m0: tuple = (float(np.cos(1.1)), 0.0, float(np.sin(1.1)))
    t_end: float = 10.0
    reference: tuple = (0.40706613658804081086, 0.283007426812844076, 0.86844916766156164371)


STANDARD_CASE = StandardCase()

# The seed paper's symmetric body (I1 = I2 > I3 > 0) used by the default simulation.
PAPER_BODY = (2.0, 2.0, 1.0)
PAPER_M0 = (0.6, 0.0, 0.8)
