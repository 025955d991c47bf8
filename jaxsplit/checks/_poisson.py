"""Structure checks for ANY map ``step(x, h)`` on any state, and for Poisson matrices.

* Poisson (seed paper, Observation 3.1, (3.2)): Φ is Poisson for Π iff
  DΦ(x) Π(x) DΦ(x)ᵀ = Π(Φ(x)) for all x. ``poisson_defect`` returns the max-norm of the
  difference, with DΦ from ``jax.jacfwd``.
* Symplectic (Definition 2.2 with ω = Σ dp ∧ dq): DΦᵀ J DΦ = J, x = (q, p).
* Symplectic on the coadjoint orbits of so(3)* (Proposition 4.2): the spheres |m| = k
  carry the Kirillov–Kostant–Souriau form ω_m(u, v) = −m·(u × v)/|m|² (the form with
  ω(X_F, X_G) = {F, G} for Π = hat(m)); ``orbit_symplectic_defect`` measures
  |ω_{Φ(m)}(DΦ u, DΦ v) − ω_m(u, v)| on an orthonormal tangent basis (u, v) at m, together
  with the Casimir change that decides whether Φ maps orbits to orbits at all.

* Jacobi (of a Poisson matrix function itself): Π skew and the Jacobi identity's cyclic
  sum zero; ``jacobi_defect`` checks a user's Π(x) with ∂Π from ``jax.jacfwd``.

States may be any PyTree: the checks ravel the floating leaves into one vector
(``jaxsplit.core.state.ravel``) and Π(x) is written in those coordinates.
Every defect is a pure function of (x, h) and vmaps. ``defect_summary`` evaluates one
over a sample of points and step sizes in one compiled call and reports the maximum and
where it is attained; ``growth_exponent`` fits defect ∝ h^p.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._bounds import count, fits
from ..core._errors import InputError
from ..core._integrate import step_size
from ..core._state import as_state, float_dtype, leading_size, ravel


def _state(x):
    """A single state as a PyTree of arrays (vmap for many)."""
    return as_state(x, "the state")


def _vector(x):
    x = _state(x)
    if not (hasattr(x, "ndim") and x.ndim == 1):
        raise InputError(f"this check acts on a single state x in R^n (vmap for many), got {type(x).__name__} "
                         f"of shape {getattr(x, 'shape', None)}")
    return x


def _map(step, x, h):
    h = step_size(h)  # a finite real scalar (where concrete), as integrate's
    return lambda y: step(y, h)


def _flat_map(step, x, h):
    """(flat x, Φ on flat vectors, unravel) for a map of any PyTree state."""
    flat, unravel = ravel(x)
    h = jnp.asarray(step_size(h), dtype=flat.dtype)
    return flat, (lambda v: ravel(step(unravel(v), h))[0]), unravel


def _poisson_fn(poisson_matrix):
    """A system (its ``poisson_matrix`` method) or a function x -> Π(x)."""
    fn = getattr(poisson_matrix, "poisson_matrix", poisson_matrix)
    if not callable(fn):
        raise InputError(f"poisson_matrix must be a function x -> Π(x) or a system, got {poisson_matrix!r}")
    return fn


def _square(pi, n: int, where: str):
    pi = jnp.asarray(pi)
    if pi.shape != (n, n):
        raise InputError(f"the checks act on a single state (vmap for many): Π(x) must be ({n}, {n}) over the "
                         f"{n} floating components of the state (in ravel order), got shape {pi.shape} {where}")
    return pi


def poisson_defect(step: Callable, poisson_matrix: Callable, x, h):
    """max |DΦ(x) Π(x) DΦ(x)ᵀ − Π(Φ(x))| for Φ = step(·, h), on any PyTree state.

    ``poisson_matrix`` is a function x -> Π(x) ((n, n) over the n floating components of
    the state in ravel order) or a system. DΦ by ``jax.jacfwd`` on the raveled floating
    leaves; integer leaves ride along unchanged. Returns a scalar array in the state's dtype;
    pure JAX (``x`` and ``h`` traced: ``vmap`` it, or use ``poisson_summary``).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m = jnp.array([0.6, 0.0, 0.8])
    >>> float(jaxsplit.poisson_defect(jaxsplit.splitting(body, "strang"), body, m, 0.3)) < 1e-15
    True
    >>> float(jaxsplit.poisson_defect(jaxsplit.rk4(body), body, m, 0.3)) > 1e-6     # not Poisson
    True
    """
    x = _state(x)
    pi = _poisson_fn(poisson_matrix)
    flat, phi, unravel = _flat_map(step, x, h)
    n = flat.shape[0]
    pi_x = _square(pi(x), n, "at x")  # before the Jacobian: a batch of states is refused at once
    jac = jax.jacfwd(phi)(flat)
    lhs = jac @ pi_x @ jac.T
    return jnp.max(jnp.abs(lhs - _square(pi(unravel(phi(flat))), n, "at Φ(x)")))


def jacobi_defect(poisson_matrix: Callable, x):
    """How far Π is from a Poisson structure at x: the max of |Π + Πᵀ| (skew symmetry) and
    of the Jacobi identity's cyclic sum Σ_l Π_il ∂_l Π_jk + Π_jl ∂_l Π_ki + Π_kl ∂_l Π_ij,
    with ∂Π by ``jax.jacfwd``; any PyTree state (floating leaves raveled). A scalar array;
    traced like ``poisson_defect``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> float(jaxsplit.jacobi_defect(body, jnp.array([0.3, -0.5, 0.8])))
    0.0
    >>> float(jaxsplit.jacobi_defect(lambda x: jnp.array([[0.0, 1.0], [0.0, 0.0]]), jnp.zeros(2)))  # not skew
    1.0
    """
    x = _state(x)
    pi = _poisson_fn(poisson_matrix)
    flat, unravel = ravel(x)
    n = flat.shape[0]

    def matrix(v):
        return _square(pi(unravel(v)), n, "")

    p = matrix(flat)
    dp = jax.jacfwd(matrix)(flat)  # dp[j, k, l] = ∂_l Π_jk
    t = jnp.einsum("il,jkl->ijk", p, dp)
    cyclic = t + jnp.transpose(t, (1, 2, 0)) + jnp.transpose(t, (2, 0, 1))
    return jnp.maximum(jnp.max(jnp.abs(p + p.T)), jnp.max(jnp.abs(cyclic)))


def canonical_j(dim: int, dtype=None):
    if dim % 2:
        raise InputError(f"a canonical symplectic form needs an even dimension, got {dim}")
    m = dim // 2
    eye, zero = jnp.eye(m, dtype=dtype), jnp.zeros((m, m), dtype=dtype)
    return jnp.block([[zero, eye], [-eye, zero]])


def symplectic_defect(step: Callable, x, h, j=None):
    """max |DΦ(x)ᵀ J DΦ(x) − J|; J = [[0, I], [−I, 0]] for x = (q, p) of shape (2m,) unless given
    (an (n, n) array). A scalar array; ``x``, ``h`` traced.

    >>> import jax.numpy as jnp, jaxsplit
    >>> def verlet(x, h):                          # symplectic
    ...     p = x[1] - h / 2 * x[0]; q = x[0] + h * p
    ...     return jnp.stack([q, p - h / 2 * q])
    >>> float(jaxsplit.symplectic_defect(verlet, jnp.array([1.0, 0.0]), 0.1)) < 1e-15
    True
    >>> euler = lambda x, h: x + h * jnp.stack([x[1], -x[0]])        # explicit Euler: defect h²
    >>> round(float(jaxsplit.symplectic_defect(euler, jnp.array([1.0, 0.0]), 0.1)), 12)
    0.01
    """
    x = _vector(x)
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
    """|ω_{Φ(m)}(DΦ u, DΦ v) − ω_m(u, v)| + ||Φ(m)|² − |m|²|/|m|² for a map of so(3)* = R³:
    does Φ keep the sphere and its KKS area form? ``m`` (3,), a scalar array; traced.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> float(jaxsplit.orbit_symplectic_defect(jaxsplit.splitting(body, "strang"), jnp.array([0.6, 0.0, 0.8]), 0.2)) < 1e-15
    True
    """
    m = _vector(m)
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
    """A defect over a sample: its maximum and where it is attained (``PoissonSummary`` is the same).

    ``max`` (float), ``x`` (the worst state, NumPy leaves), ``h`` (float), ``index`` (int),
    ``defects`` (NumPy (N,)): concrete values, for reports.

    >>> import jax.numpy as jnp, jaxsplit
    >>> s = jaxsplit.defect_summary(lambda x, h: h * x[0], jnp.array([[1.0], [3.0], [2.0]]), 0.5)
    >>> s.max, s.index, s.x.tolist()
    (1.5, 1, [3.0])
    """

    max: float
    x: object  # the state of the worst sample (arrays, or a PyTree of arrays)
    h: float  # its step size
    index: int
    defects: np.ndarray  # every sample's defect


PoissonSummary = DefectSummary


def _sample(xs, hs):
    """States (a PyTree whose leaves share a leading axis N) and N step sizes (or a scalar)."""
    xs = as_state(xs, "sample states")
    n = leading_size(xs, "sample states")
    if isinstance(xs, jax.Array) and xs.ndim < 2:
        raise InputError(f"sample states must have shape (N, n), got {xs.shape}")
    dtype = float_dtype(xs)
    hs = jnp.broadcast_to(jnp.asarray(hs, dtype=dtype), (n,)) if jnp.ndim(hs) == 0 else jnp.asarray(hs, dtype)
    if hs.shape != (n,):
        raise InputError(f"need one step size per state ({n}) or a scalar, got shape {hs.shape}")
    if not isinstance(hs, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(hs))):
        raise InputError(f"step sizes must be finite, got {np.asarray(hs)[~np.isfinite(np.asarray(hs))][:3].tolist()}")
    return xs, hs


def _summary(values, xs, hs) -> DefectSummary:
    values = np.asarray(values)
    finite = np.isfinite(values)
    k = int(np.nanargmax(values)) if finite.any() else 0
    worst = float(np.nanmax(values)) if finite.any() else float("nan")
    if np.any(np.isnan(values)):
        worst, k = float("nan"), int(np.argmax(np.isnan(values)))
    x = jax.tree_util.tree_map(lambda a: np.asarray(a[k]), xs)
    return DefectSummary(worst, x, float(hs[k]), k, values)


def defect_summary(defect: Callable, xs, hs) -> DefectSummary:
    """Evaluate ``defect(x, h)`` over states ``xs`` (N, ...) and step sizes ``hs`` (N,) or scalar.

    One compilation for the whole sample (``jit(vmap(defect))``); ``xs`` may be any PyTree
    whose leaves share the leading axis N. Returns a ``DefectSummary`` (concrete).

    >>> import jax.numpy as jnp, jaxsplit
    >>> jaxsplit.defect_summary(lambda x, h: jnp.abs(x @ x - 1), jnp.eye(3), 0.1).max
    0.0
    """
    xs, hs = _sample(xs, hs)
    return _summary(jax.jit(jax.vmap(defect))(xs, hs), xs, hs)


def poisson_summary(step: Callable, poisson_matrix: Callable, xs, hs) -> DefectSummary:
    """``poisson_defect`` over a sample (maximum and where it is attained): a ``DefectSummary``.

    >>> import jax, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> xs = jax.random.normal(jax.random.PRNGKey(0), (16, 3))
    >>> jaxsplit.poisson_summary(jaxsplit.splitting(body, "strang"), body, xs, 0.2).max < 1e-14
    True
    """
    return defect_summary(lambda x, h: poisson_defect(step, poisson_matrix, x, h), xs, hs)


def jacobi_summary(poisson_matrix: Callable, xs) -> DefectSummary:
    """``jacobi_defect`` over a sample of states (``h`` is reported as 0): a ``DefectSummary``.

    >>> import jax, jaxsplit
    >>> xs = jax.random.normal(jax.random.PRNGKey(0), (8, 3))
    >>> jaxsplit.jacobi_summary(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), xs).max < 1e-15
    True
    """
    return defect_summary(lambda x, h: jacobi_defect(poisson_matrix, x), xs, 0.0)


def symplectic_summary(step: Callable, xs, hs, j=None) -> DefectSummary:
    """``symplectic_defect`` over a sample: a ``DefectSummary``.

    >>> import jax, jax.numpy as jnp, jaxsplit
    >>> euler = lambda x, h: x + h * jnp.stack([x[1], -x[0]])     # explicit Euler: area grows by 1 + h²
    >>> round(jaxsplit.symplectic_summary(euler, jnp.ones((4, 2)), jnp.array([0.1, 0.2, 0.3, 0.4])).max, 12)
    0.16
    """
    return defect_summary(lambda x, h: symplectic_defect(step, x, h, j), xs, hs)


def growth_exponent(hs, defects, floor: float = 1e-13) -> float:
    """Slope p of log(defect) against log(h) (defect ∝ h^p), over points above ``floor``
    (NumPy, concrete values; fewer than 2 usable points raise an ``InputError``).

    >>> import jaxsplit
    >>> round(jaxsplit.growth_exponent([0.1, 0.2, 0.4], [1e-4, 8e-4, 6.4e-3]), 6)
    3.0
    """
    h = np.abs(np.asarray(hs, dtype=float)).ravel()
    d = np.asarray(defects, dtype=float).ravel()
    use = np.isfinite(d) & (d > floor) & (h > 0)
    if use.sum() < 2:
        raise InputError(f"need >= 2 defects above {floor:g} to fit a growth exponent, got {use.sum()}")
    return float(np.polyfit(np.log(h[use]), np.log(d[use]), 1)[0])


def random_unit_states(key, n_samples: int, dim: int = 3, dtype=None):
    """States uniform on the unit sphere of Rⁿ (a sample for the checks)."""
    n_samples, dim = count(n_samples, "n_samples"), count(dim, "dim")
    dtype = dtype or jnp.result_type(float)
    fits(2 * n_samples * dim * np.dtype(dtype).itemsize, f"{n_samples:,} random states of dimension {dim:,}",
         "draw fewer states", jax.devices()[0])
    x = jax.random.normal(key, (n_samples, dim), dtype=dtype)
    return x / jnp.linalg.norm(x, axis=1, keepdims=True)
