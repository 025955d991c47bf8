"""Ruth's integrator (2.6) of the seed paper: symplectic Euler for a separable H = T(p) + V(q).

q_{n+1} = q_n + h ∇T(p_n), p_{n+1} = p_n − h ∇V(q_{n+1}).
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._errors import InputError


def _half_square(v):
    return 0.5 * jnp.sum(v * v)


class Ruth(eqx.Module):
    """Ruth's first-order symplectic map (2.6) for H = T(p) + V(q), state x = (q, p).

    q_{n+1} = q_n + h ∇T(p_n),  p_{n+1} = p_n − h ∇V(q_{n+1}). With T = V = ½|·|² this is
    exactly (2.6): x¹ ← x¹ + h x², x² ← −h x¹ + (1 − h²) x².
    """

    potential: Callable = eqx.field(static=True, default=_half_square)
    kinetic: Callable = eqx.field(static=True, default=_half_square)

    def __call__(self, x, h):
        x = jnp.asarray(x)
        if x.ndim != 1 or x.shape[0] % 2:
            raise InputError(f"the Ruth map acts on x = (q, p) of even length, got shape {x.shape}")
        h = jnp.asarray(h, dtype=x.dtype)
        m = x.shape[0] // 2
        q, p = x[:m], x[m:]
        q = q + h * jax.grad(self.kinetic)(p)
        p = p - h * jax.grad(self.potential)(q)
        return jnp.concatenate([q, p])


def ruth(potential: Callable = _half_square, kinetic: Callable = _half_square) -> Ruth:
    """The Ruth integrator (2.6) for H = T(p) + V(q) (``kinetic``, ``potential``: functions of
    (m,) arrays, static); defaults give Example 2.1's harmonic oscillator. The step acts on
    x = (q, p) of shape (2m,) in x's dtype.

    >>> import jax.numpy as jnp, jaxsplit
    >>> step = jaxsplit.ruth()
    >>> step(jnp.array([1.0, 0.0]), 0.1).tolist()                  # x¹ + h x², −h x¹ + (1 − h²) x²
    [1.0, -0.1]
    >>> float(jaxsplit.symplectic_defect(step, jnp.array([0.3, 0.7]), 0.1)) < 1e-15
    True
    """
    if not callable(potential) or not callable(kinetic):
        raise InputError("ruth needs callables potential(q) and kinetic(p)")
    return Ruth(potential, kinetic)
