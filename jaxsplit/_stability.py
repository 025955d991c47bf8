"""Linear stability of a splitting at the relative equilibria of the free rigid body.

Steady rotation about a principal axis, m = e_i (|m| = 1), is a fixed point of the exact
flow and of every splitting map built from axis rotations (a rotation about axis j ≠ i
turns e_i by the angle ∝ m_j = 0; a rotation about axis i fixes it). The map's Jacobian DΦ
(``jax.jacfwd``) has the eigenvalue 1 along e_i (|m| is conserved) and leaves the tangent
plane of the sphere invariant; its 2×2 tangent block B has det B = 1 (a Poisson map is
area preserving on the symplectic leaf), so its eigenvalues are e^{±iθ} while |tr B| < 2
(linearly stable, elliptic) or real μ, 1/μ once |tr B| > 2 (unstable, hyperbolic).

The exact linearisation at e_i, with w = 1/I: at e_1, δ̇_2 = (w_1 − w_3) δ_3 and
δ̇_3 = (w_2 − w_1) δ_2, and in general λ² = (w_i − w_a)(w_b − w_i) with (a, b) the other
two axes: the exact time-h flow has
eigenvalues e^{±hλ}, elliptic (λ² < 0, angle h√(−λ²)) for the largest and smallest moment,
hyperbolic for the middle one. A discrete map can lose stability where the flow is stable
(a resonance once the rotation angle per step gets large) or gain a spurious stability
at the middle axis; ``stability_map`` locates both on a grid of (h, body).
"""

import jax
import jax.numpy as jnp
import numpy as np

from ._body import RigidBody
from ._compose import roll
from ._errors import InputError
from ._schemes import schemes
from ._splitting import SPLITS, splitting
from ._sweep import _grouped, _shift_axes

STABILITY_TOL = 1e-9  # spectral radius above 1 + this counts as unstable


def _tangent_block(jac, axis: int):
    others = [k for k in range(3) if k != axis]
    return jac[jnp.ix_(jnp.asarray(others), jnp.asarray(others))]


def _kernel(scheme, split, shift):
    def one(h, inertia):
        step = roll(splitting(RigidBody(inertia), scheme, split, shift_axis=shift))
        eye = jnp.eye(3, dtype=inertia.dtype)
        out = []
        for axis in range(3):
            jac = jax.jacfwd(lambda y: step(y, h))(eye[axis])
            block = _tangent_block(jac, axis)
            out.append((jnp.trace(block), jnp.linalg.det(block), jac[axis, axis],
                        jnp.max(jnp.abs(step(eye[axis], h) - eye[axis]))))
        return tuple(jnp.stack(v) for v in zip(*out))

    return jax.jit(jax.vmap(jax.vmap(one, in_axes=(None, 0)), in_axes=(0, None)))


def _exact_lambda2(inertia):
    """λ² of the exact linearisation at e_1, e_2, e_3 (|m| = 1), shape (..., 3)."""
    w = 1 / inertia
    out = []
    for i in range(3):
        a, b = (k for k in range(3) if k != i)
        out.append((w[..., i] - w[..., a]) * (w[..., b] - w[..., i]))
    return np.stack(out, axis=-1)


def stability_map(scheme, step_sizes, inertias, *, split: str = "axes", shift_axis="auto",
                  tol: float = STABILITY_TOL) -> dict:
    """Linear stability at m = e_1, e_2, e_3 for every (h, body); arrays (n_h, n_bodies, 3).

    ``step_sizes`` (n_h,) > 0; ``inertias`` (n_bodies, 3) > 0 (or (2,) ratio pairs are
    not accepted: pass I = (1, I2/I1, I3/I1)). Returns ``eigenvalues`` (complex, last axis:
    1 along e_i then the two tangent ones), ``spectral_radius``, ``trace``, ``det`` (of
    the tangent block; 1 for a Poisson map), ``angle`` (discrete rotation angle per step,
    NaN where hyperbolic), ``stable``; the exact flow's ``exact_spectral_radius``,
    ``exact_angle``, ``exact_stable``; ``fixed_point_error`` (max|Φ(e_i) − e_i|);
    ``first_unstable_h`` (n_bodies, 3): the smallest grid h at which the map is unstable
    where the exact flow is stable (NaN if none), and ``first_spurious_h``: the smallest
    grid h at which the map is stable where the flow is not.
    """
    scheme = schemes.resolve(scheme)
    if split not in SPLITS:
        raise InputError(f"split must be one of {SPLITS}, got {split!r}")
    h = np.atleast_1d(np.asarray(step_sizes))
    inertia = np.asarray(inertias)
    if h.ndim != 1 or len(h) == 0 or not np.all(np.isfinite(h) & (h > 0)):
        raise InputError(f"step_sizes must be positive finite numbers, got {np.asarray(step_sizes).tolist()}")
    if inertia.ndim == 1:
        inertia = inertia[None]
    if inertia.ndim != 2 or inertia.shape[1] != 3 or not np.all(np.isfinite(inertia) & (inertia > 0)):
        raise InputError(f"inertias must be positive, shape (n, 3); got shape {inertia.shape}")
    if not (isinstance(tol, float) and tol >= 0):
        raise InputError(f"tol must be a float >= 0, got {tol!r}")
    dtype = np.result_type(h.dtype, inertia.dtype, jnp.result_type(float))
    h, inertia = h.astype(dtype), inertia.astype(dtype)
    axes = _shift_axes(inertia, shift_axis) if split == "casimir" else np.zeros(len(inertia), int)

    def run(axis, idx):
        shift = axis if split == "casimir" else "auto"
        res = _kernel(scheme, split, shift)(jnp.asarray(h), jnp.asarray(inertia[idx]))
        return [np.moveaxis(np.asarray(r), 1, 0) for r in res]  # bodies first for _grouped

    trace, det, radial, fixed = (np.moveaxis(r, 0, 1) for r in _grouped(axes, run))
    disc = np.sqrt((trace * trace - 4 * det).astype(complex))
    mu = np.stack([(trace + disc) / 2, (trace - disc) / 2], axis=-1)
    eigenvalues = np.concatenate([radial[..., None].astype(complex), mu], axis=-1)
    radius = np.max(np.abs(mu), axis=-1)
    with np.errstate(invalid="ignore"):
        angle = np.where(np.abs(trace) <= 2, np.arccos(np.clip(trace / 2, -1, 1)), np.nan)
    lam2 = _exact_lambda2(inertia)[None]
    hh = h[:, None, None]
    exact_radius = np.exp(hh * np.sqrt(np.maximum(lam2, 0)))
    exact_stable = np.broadcast_to(lam2 <= 0, radius.shape)
    exact_angle = np.where(lam2 <= 0, hh * np.sqrt(np.maximum(-lam2, 0)), np.nan)
    stable = radius <= 1 + tol

    order = np.argsort(h)

    def first(mask):
        hit = np.any(mask, axis=0)
        return np.where(hit, h[order][np.argmax(mask, axis=0)], np.nan)

    return {
        "step_sizes": h, "inertias": inertia,
        "eigenvalues": eigenvalues, "spectral_radius": radius, "trace": trace, "det": det,
        "angle": angle, "stable": stable,
        "exact_spectral_radius": exact_radius, "exact_angle": exact_angle, "exact_stable": exact_stable,
        "fixed_point_error": fixed,
        "first_unstable_h": first((~stable & exact_stable)[order]),
        "first_spurious_h": first((stable & ~exact_stable)[order]),
    }
