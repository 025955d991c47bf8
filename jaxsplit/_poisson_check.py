"""Structure checks for ANY map on Rⁿ given as a pure function ``step(x, h)``.

* Poisson (seed paper, Observation 3.1, (3.2)): Φ is Poisson for Π iff
  DΦ(x) Π(x) DΦ(x)ᵀ = Π(Φ(x)) for all x. ``poisson_defect`` returns the max-norm of the
  difference, with DΦ from ``jax.jacfwd``.
* Symplectic (Definition 2.2 with ω = Σ dp ∧ dq): DΦᵀ J DΦ = J, x = (q, p).
* Symplectic on the coadjoint orbits of so(3)* (Proposition 4.2): the spheres |m| = k
  carry the Kirillov–Kostant–Souriau form ω_m(u, v) = −m·(u × v)/|m|² (the form with
  ω(X_F, X_G) = {F, G} for Π = hat(m)); ``orbit_symplectic_defect`` measures
  |ω_{Φ(m)}(DΦ u, DΦ v) − ω_m(u, v)| on an orthonormal tangent basis (u, v) at m, together
  with the Casimir change that decides whether Φ maps orbits to orbits at all.

Every defect is a pure function of (x, h) and vmaps. ``defect_summary`` evaluates one
over a sample of points and step sizes in one compiled call and reports the maximum and
where it is attained; ``growth_exponent`` fits defect ∝ h^p.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import InputError


def _state(x):
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    if x.ndim != 1:
        raise InputError(f"the checks act on a single state x in R^n (vmap for many), got shape {x.shape}")
    return x


def _map(step, x, h):
    h = jnp.asarray(h, dtype=x.dtype)
    return lambda y: step(y, h)


def poisson_defect(step: Callable, poisson_matrix: Callable, x, h):
    """max |DΦ(x) Π(x) DΦ(x)ᵀ − Π(Φ(x))| for Φ = step(·, h)."""
    x = _state(x)
    phi = _map(step, x, h)
    jac = jax.jacfwd(phi)(x)
    lhs = jac @ poisson_matrix(x) @ jac.T
    return jnp.max(jnp.abs(lhs - poisson_matrix(phi(x))))


def canonical_j(dim: int, dtype=None):
    if dim % 2:
        raise InputError(f"a canonical symplectic form needs an even dimension, got {dim}")
    m = dim // 2
    eye, zero = jnp.eye(m, dtype=dtype), jnp.zeros((m, m), dtype=dtype)
    return jnp.block([[zero, eye], [-eye, zero]])


def symplectic_defect(step: Callable, x, h, j=None):
    """max |DΦ(x)ᵀ J DΦ(x) − J|; J = [[0, I], [−I, 0]] for x = (q, p) unless given."""
    x = _state(x)
    j = canonical_j(x.shape[0], x.dtype) if j is None else jnp.asarray(j, dtype=x.dtype)
    if j.shape != (x.shape[0], x.shape[0]):
        raise InputError(f"J must be {x.shape[0]} x {x.shape[0]}, got shape {j.shape}")
    jac = jax.jacfwd(_map(step, x, h))(x)
    return jnp.max(jnp.abs(jac.T @ j @ jac - j))


def kks_form(m, u, v):
    """The KKS form of the sphere through m: ω_m(u, v) = −m·(u × v)/|m|²."""
    return -jnp.dot(m, jnp.cross(u, v)) / jnp.dot(m, m)


def _tangent_basis(m):
    n = m / jnp.linalg.norm(m)
    # the coordinate axis least aligned with n, projected: well conditioned
    e = jnp.eye(3, dtype=m.dtype)[jnp.argmin(jnp.abs(n))]
    u = e - jnp.dot(e, n) * n
    u = u / jnp.linalg.norm(u)
    return u, jnp.cross(n, u)


def orbit_symplectic_defect(step: Callable, m, h):
    """|ω_{Φ(m)}(DΦ u, DΦ v) − ω_m(u, v)| + ||Φ(m)|² − |m|²|/|m|² for a map of so(3)* = R³."""
    m = _state(m)
    if m.shape != (3,):
        raise InputError(f"coadjoint orbits of so(3)* need m in R^3, got shape {m.shape}")
    phi = _map(step, m, h)
    jac = jax.jacfwd(phi)(m)
    u, v = _tangent_basis(m)
    y = phi(m)
    area = jnp.abs(kks_form(y, jac @ u, jac @ v) - kks_form(m, u, v))
    casimir = jnp.abs(jnp.dot(y, y) - jnp.dot(m, m)) / jnp.dot(m, m)
    return area + casimir


class DefectSummary(NamedTuple):
    """A defect over a sample: its maximum and where it is attained."""

    max: float
    x: np.ndarray  # the state of the worst sample
    h: float  # its step size
    index: int
    defects: np.ndarray  # every sample's defect


PoissonSummary = DefectSummary


def _sample(xs, hs):
    xs = jnp.asarray(xs)
    if not jnp.issubdtype(xs.dtype, jnp.floating):
        xs = xs.astype(jnp.result_type(float))
    if xs.ndim != 2:
        raise InputError(f"sample states must have shape (N, n), got {xs.shape}")
    hs = jnp.broadcast_to(jnp.asarray(hs, dtype=xs.dtype), xs.shape[:1]) if jnp.ndim(hs) == 0 else jnp.asarray(hs, xs.dtype)
    if hs.shape != xs.shape[:1]:
        raise InputError(f"need one step size per state ({xs.shape[0]}) or a scalar, got shape {hs.shape}")
    return xs, hs


def defect_summary(defect: Callable, xs, hs) -> DefectSummary:
    """Evaluate ``defect(x, h)`` over states ``xs`` (N, n) and step sizes ``hs`` (N,) or scalar.

    One compilation for the whole sample (``jit(vmap(defect))``).
    """
    xs, hs = _sample(xs, hs)
    values = np.asarray(jax.jit(jax.vmap(defect))(xs, hs))
    k = int(np.nanargmax(values)) if np.any(np.isfinite(values)) else 0
    worst = float(np.nanmax(values)) if np.any(np.isfinite(values)) else float("nan")
    if np.any(np.isnan(values)):
        worst, k = float("nan"), int(np.argmax(np.isnan(values)))
    return DefectSummary(worst, np.asarray(xs[k]), float(hs[k]), k, values)


def poisson_summary(step: Callable, poisson_matrix: Callable, xs, hs) -> DefectSummary:
    """``poisson_defect`` over a sample (maximum and where it is attained)."""
    return defect_summary(lambda x, h: poisson_defect(step, poisson_matrix, x, h), xs, hs)


def symplectic_summary(step: Callable, xs, hs, j=None) -> DefectSummary:
    """``symplectic_defect`` over a sample."""
    return defect_summary(lambda x, h: symplectic_defect(step, x, h, j), xs, hs)


def growth_exponent(hs, defects, floor: float = 1e-13) -> float:
    """Slope p of log(defect) against log(h) (defect ∝ h^p), over points above ``floor``."""
    h = np.abs(np.asarray(hs, dtype=float)).ravel()
    d = np.asarray(defects, dtype=float).ravel()
    use = np.isfinite(d) & (d > floor) & (h > 0)
    if use.sum() < 2:
        raise InputError(f"need >= 2 defects above {floor:g} to fit a growth exponent, got {use.sum()}")
    return float(np.polyfit(np.log(h[use]), np.log(d[use]), 1)[0])


def random_unit_states(key, n_samples: int, dim: int = 3, dtype=None):
    """States uniform on the unit sphere of Rⁿ (a sample for the checks)."""
    x = jax.random.normal(key, (n_samples, dim), dtype=dtype or jnp.result_type(float))
    return x / jnp.linalg.norm(x, axis=1, keepdims=True)
