"""Fitting a free rigid body's inertia to an observed m(t): identifiability and the gauge.

What m(t) can tell (identifiability)
------------------------------------
Write w = (1/I1, 1/I2, 1/I3). The equations ṁ = m × (w ⊙ m) are unchanged by
w → w + c·(1, 1, 1): the shift adds c·m × m = 0 (the Hamiltonian changes by c·C, and the
Casimir C commutes with everything). So an observed m(t) determines exactly two numbers of
the body, the differences w1 − w3 and w2 − w3 (their magnitudes too, since the time axis
is observed), and nothing else. The ratios I2/I1 = w1/w2 and I3/I1 = w1/w3 change along
the unobservable direction c, so they are NOT identifiable from m(t) alone; neither is the
overall scale. (Conversely a rescaled body I → λI is not an equivalent explanation: it
changes the time scale.) In log-inertia coordinates u = log I the unobservable direction is
du ∝ −(I1, I2, I3); the Gauss–Newton Hessian of the misfit has it as its null vector
(``FitResult.null_direction``, checked in the tests).

``fit_inertia`` therefore works in two stages:

1. *Trajectory fit* of the identifiable part: log I2, log I3 and (optionally) m0, with I1
   held at a reference value chosen so every moment stays positive near the optimum
   (the inertia is parametrised by its logarithm, so it cannot turn negative). The start
   comes from integral matching: m_{k+1} − m_k ≈ ½Δt (A(m_k) + A(m_{k+1})) w is linear in
   w and is solved by least squares (minimum norm along the null direction). Then Adam,
   then L-BFGS (``_minimise``) minimise the mean squared misfit through the integrator.
2. *Gauge*: one extra piece of information fixes c in closed form, either a known kinetic
   energy E = ½ Σ w_i m0_i² (``energy=``, with its standard deviation ``energy_sigma``) or
   a known moment I1 (``inertia1=``). With neither, I1 = 1 (the data's units) is ASSUMED,
   and ``FitResult.gauge`` says so. ``ratio_range`` gives the ratios over every gauge
   that keeps all moments positive — what m(t) alone allows.

Uncertainty: the Gauss–Newton covariance σ̂² (JᵀJ)⁻¹ of stage 1 (σ̂² = RSS / (3n − p)),
propagated to the ratios with the Jacobian of the gauge map (delta method), the energy's
variance included.

The optimisation, the checkpointed model and the Gauss–Newton curvature are the generic
ones of ``jaxsplit.explore.fit`` (any system); this module adds the rigid body's gauge.
"""

import functools
import math
import time
from typing import NamedTuple

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._schemes import schemes
from ..systems._rigid_body import RigidBody
from ._fit import minimise, predict, substeps


# ------------------------------------------------------------------ data checks
def _check_observations(t, m):
    for name, value in (("t", t), ("m", m)):
        if np.iscomplexobj(value):  # a cast to float would drop the imaginary part silently
            raise InputError(f"observations {name} must be real, got dtype {np.asarray(value).dtype}")
    try:
        t = np.asarray(t, dtype=float)
        m = np.asarray(m, dtype=float)
    except (TypeError, ValueError) as err:
        raise InputError(f"observations must be numeric arrays: {err}") from err
    if t.ndim != 1 or len(t) < 4:
        raise InputError(f"t must have shape (n,) with n >= 4, got shape {t.shape}")
    if m.shape != (len(t), 3):
        raise InputError(f"m must have shape (n, 3) = ({len(t)}, 3) matching t, got {m.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(m))):
        raise InputError("observations t and m must be finite (no NaN or inf)")
    if np.any(np.diff(t) <= 0):
        raise InputError("t must be strictly increasing")
    return t, m


# ------------------------------------------------------------------ model
def _a_matrix(m):
    """A(m) with ṁ = m × (w ⊙ m) = A(m) w: column i is m_i (m × e_i). Shape (..., 3, 3)."""
    eye = np.eye(3)
    return np.stack([m[..., i, None] * np.cross(m, eye[i]) for i in range(3)], axis=-1)


IDENTIFIABLE_TOL = 1e-8  # second singular value of the matching matrix relative to the first


def integral_matching(t, m) -> np.ndarray:
    """Least-squares w = 1/I from m_{k+1} − m_k ≈ ½Δt (A(m_k) + A(m_{k+1})) w.

    Minimum-norm solution: the component along (1, 1, 1) is not determined by m(t) (it is
    the matrix's exact null vector). The two differences must be: data whose matrix has
    a second singular value below ``IDENTIFIABLE_TOL`` times the first (m = 0, or m at
    rest on a principal axis, where every A(m) vanishes) determine no inertia, and are
    refused rather than fitted.
    """
    t, m = _check_observations(t, m)
    a = (0.5 * np.diff(t)[:, None, None] * (_a_matrix(m[:-1]) + _a_matrix(m[1:]))).reshape(-1, 3)
    sv = np.linalg.svd(a, compute_uv=False)
    if not sv[1] > IDENTIFIABLE_TOL * sv[0]:
        raise InputError("the observations do not determine the inertia: m(t) is zero, or rests on a principal "
                         f"axis, or moves so that only {int(sv[0] > 0)} of the 2 identifiable combinations of the "
                         f"moments shows (singular values {sv[0]:.2g}, {sv[1]:.2g})")
    w, *_ = np.linalg.lstsq(a, np.diff(m, axis=0).reshape(-1), rcond=None)
    return w


def _body(log_inertia):
    return RigidBody(jnp.exp(log_inertia), allow_nonphysical=True)  # a fit may pass through any positive body


def _predict(scheme, shift, n_sub: int, log_inertia, m0, dts):
    """m at every observation time (the generic ``fit.predict`` on the Casimir split)."""
    return predict(_body, log_inertia, m0, dts, scheme=scheme, split="casimir", options=(("shift", shift),),
                   n_sub=n_sub)


_predict_jit = jax.jit(_predict, static_argnums=(0, 1, 2))


class FitResult(NamedTuple):
    """Outcome of ``fit_inertia`` (NumPy arrays and floats; see the module docstring): the
    inertia (3,) under the stated ``gauge``, the identifiable ``inverse_differences`` and the
    ``ratio_range`` the data allow over all gauges, with Gauss–Newton standard deviations and
    diagnostics; ``as_dict()`` for JSON. See ``fit_inertia`` for a run.

    >>> import jaxsplit
    >>> jaxsplit.FitResult._fields[:4]
    ('inertia', 'inertia_ratios', 'ratio_std', 'inverse_differences')
    """

    inertia: np.ndarray  # (3,) under the gauge
    inertia_ratios: np.ndarray  # (I2/I1, I3/I1)
    ratio_std: np.ndarray  # Gauss–Newton (delta-method) standard deviations
    inverse_differences: np.ndarray  # identifiable: (1/I1 − 1/I3, 1/I2 − 1/I3)
    inverse_differences_std: np.ndarray
    m0: np.ndarray
    loss: float  # final mean squared misfit per component
    noise_sigma: float  # σ̂ from the residuals
    iterations: int  # Adam + L-BFGS iterations
    gauge: str
    ratio_range: np.ndarray  # (2, 2): [min, max] of each ratio over all positive gauges
    null_direction: np.ndarray  # GN null vector in log-inertia coordinates (unit)
    null_alignment: float  # |cos| between it and the predicted direction ∝ I (stage-1 gauge)
    hessian_eigenvalues: np.ndarray  # of the GN Hessian over (log I1, log I2, log I3)
    seconds: float

    def as_dict(self) -> dict:
        out = {}
        for k, v in self._asdict().items():
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return out


def _gauge_shift(w, m0, energy, inertia1):
    """c with w + c·1 matching the energy ½ Σ (w_i + c) m0_i² = E, or 1/I1."""
    if energy is not None:
        return (2 * energy - jnp.sum(w * m0 * m0)) / jnp.sum(m0 * m0)
    return 1 / inertia1 - w[0]


def _unpack(p, log_i1, obs, fit_m0: bool):
    log_inertia = jnp.concatenate([log_i1[None], p["log_i23"]])
    return log_inertia, (p["m0"] if fit_m0 else obs[0])


def _residual_fn(obs, dts, log_i1, config):
    scheme, shift, n_sub, fit_m0 = config[:4]

    def residuals(p):
        log_inertia, m0 = _unpack(p, log_i1, obs, fit_m0)
        return (_predict(scheme, shift, n_sub, log_inertia, m0, dts) - obs).reshape(-1)

    return residuals


@functools.partial(jax.jit, static_argnames=("config",))
def _optimise(params, obs, dts, log_i1, config):
    """Adam, then L-BFGS, on the mean squared misfit (one compilation per configuration
    and data shape: a new data set of the same shape reuses it)."""
    *_, adam_steps, adam_lr, lbfgs_iter, tol = config
    return minimise(_residual_fn(obs, dts, log_i1, config), params, adam_steps, adam_lr, lbfgs_iter, tol)


@functools.partial(jax.jit, static_argnames=("config",))
def _curvature(params, obs, dts, log_i1, config):
    """Residual Jacobian in the fitted parameters, RSS, and the Jacobian in (log I1, log I2, log I3)."""
    residuals = _residual_fn(obs, dts, log_i1, config)
    flat, unravel = jax.flatten_util.ravel_pytree(params)
    jac = jax.jacfwd(lambda f: residuals(unravel(f)))(flat)
    r = residuals(params)
    scheme, shift, n_sub, fit_m0 = config[:4]
    _, m0 = _unpack(params, log_i1, obs, fit_m0)

    def full(log_inertia):
        return (_predict(scheme, shift, n_sub, log_inertia, m0, dts) - obs).reshape(-1)

    return jac, jnp.sum(r * r), jax.jacfwd(full)(jnp.concatenate([log_i1[None], params["log_i23"]]))


@functools.partial(jax.jit, static_argnames=("fit_m0", "by_energy"))
def _gauge(params, log_i1, obs, energy, inertia1, fit_m0: bool, by_energy: bool):
    """The gauge map flat params -> (ratios, differences, 1/I under the gauge), with its Jacobians
    in the params and in the energy: one compiled program (op by op it compiled dozens)."""
    flat, unravel = jax.flatten_util.ravel_pytree(params)

    def gauge_map(f, e):
        log_inertia, m0 = _unpack(unravel(f), log_i1, obs, fit_m0)
        w = jnp.exp(-log_inertia)
        c = _gauge_shift(w, m0, e if by_energy else None, inertia1)
        wg = w + c
        return jnp.concatenate([jnp.stack([wg[0] / wg[1], wg[0] / wg[2]]), (w - w[2])[:2], wg])

    return gauge_map(flat, energy), jax.jacfwd(gauge_map, 0)(flat, energy), jax.jacfwd(gauge_map, 1)(flat, energy)


def fit_inertia(t, m, *, energy: float | None = None, energy_sigma: float = 0.0,
                inertia1: float | None = None, fit_m0: bool = True, scheme="kahan-li-6",
                max_step: float = 0.05, adam_steps: int = 50, adam_lr: float = 3e-4,
                lbfgs_iter: int = 200, tol: float = 1e-10) -> FitResult:
    """Recover the inertia ratios (and m0) from observations ``m`` (n, 3) at times ``t`` (n,).

    The gauge (module docstring) comes from ``energy`` (± ``energy_sigma``) or ``inertia1``;
    with neither, I1 = 1 is assumed. The model integrates ``scheme`` (Casimir split) with
    ⌈Δt / max_step⌉ steps per observation interval. Runs in the dtype JAX gives ``float``
    (float64 when x64 is enabled: recommended). Returns a ``FitResult`` (concrete values).

    >>> import numpy as np, jaxsplit
    >>> t, m0 = np.linspace(0.0, 2.0, 9), np.array([0.6, 0.0, 0.8])
    >>> m = jaxsplit.simulate_observations([2.0, 1.0, 0.5], m0, t, noise=0.0)
    >>> energy = float(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True).hamiltonian(m0))
    >>> r = jaxsplit.fit_inertia(t, m, energy=energy, max_step=0.25, adam_steps=0, lbfgs_iter=40)
    >>> np.round(r.inertia, 6).tolist(), r.gauge
    ([2.0, 1.0, 0.5], 'energy E = 0.73 (sigma 0)')
    """
    t0 = time.perf_counter()
    t, m = _check_observations(t, m)
    scheme = schemes.resolve(scheme)
    if energy is not None and inertia1 is not None:
        raise InputError("give energy= or inertia1= (one gauge), not both")
    if energy is not None and not (math.isfinite(energy) and energy > 0):
        raise InputError(f"energy must be a positive number, got {energy!r}")
    if inertia1 is not None and not (math.isfinite(inertia1) and inertia1 > 0):
        raise InputError(f"inertia1 must be a positive number, got {inertia1!r}")
    if not (math.isfinite(energy_sigma) and energy_sigma >= 0):
        raise InputError(f"energy_sigma must be >= 0, got {energy_sigma!r}")
    n_sub = substeps(t, max_step)
    gauge = (f"energy E = {energy:.9g} (sigma {energy_sigma:.3g})" if energy is not None else
             f"known I1 = {inertia1:.9g}" if inertia1 is not None else
             "ASSUMED I1 = 1 (m(t) does not determine it; pass energy= or inertia1=)")
    if energy is None and inertia1 is None:
        inertia1 = 1.0

    # Stage 0: integral matching, then a reference gauge keeping every moment well positive.
    w0 = integral_matching(t, m)
    spread = max(float(np.ptp(w0)), 1e-8 * float(np.max(np.abs(w0))), 1e-300)
    w_ref = w0 - w0.min() + spread
    shift = int(np.argsort(w_ref, kind="stable")[1])
    dtype = jnp.result_type(float)
    dts = jnp.asarray(np.diff(t), dtype)
    obs = jnp.asarray(m, dtype)
    log_i1 = jnp.asarray(-np.log(w_ref[0]), dtype)

    params = {"log_i23": jnp.asarray(-np.log(w_ref[1:]), dtype),
              "m0": obs[0] if fit_m0 else jnp.zeros((0,), dtype)}
    config = (scheme, shift, n_sub, bool(fit_m0), int(adam_steps), float(adam_lr), int(lbfgs_iter), float(tol))
    params, iters, final = _optimise(params, obs, dts, log_i1, config)

    # Gauss–Newton Hessian of the identifiable problem, and of the full log-inertia one.
    jac, rss, jfull = (np.asarray(a) for a in _curvature(params, obs, dts, log_i1, config))
    n_res, n_par = jac.shape
    sigma2 = float(rss) / max(n_res - n_par, 1)
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)
    log_inertia_hat, m0_hat = _unpack(params, log_i1, obs, fit_m0)
    evals, evecs = np.linalg.eigh(jfull.T @ jfull)
    null = evecs[:, 0] * np.sign(evecs[:, 0].sum() or 1.0)

    # Gauge map (flat params, energy) -> (ratios, differences), with its Jacobian.
    e_arr = jnp.asarray(0.0 if energy is None else float(energy), dtype)
    i1_arr = jnp.asarray(1.0 if inertia1 is None else float(inertia1), dtype)
    out, jg, je = (np.asarray(a) for a in _gauge(params, log_i1, obs, e_arr, i1_arr, fit_m0=bool(fit_m0),
                                                 by_energy=energy is not None))
    var = np.einsum("ij,jk,ik->i", jg, cov, jg) + je**2 * energy_sigma**2
    wg = out[4:]
    if np.any(wg <= 0):
        raise InputError(
            f"the gauge ({gauge}) makes a moment non-positive: 1/I = {wg.tolist()}; "
            "the energy or I1 given does not fit these observations")
    d = out[2:4]
    # Ratios over every positive gauge c (all w + c > 0): each ratio is monotone in c, so
    # its range lies between its value as the smallest w + c -> 0 and its limit 1 (c -> inf).
    wf = np.asarray(jnp.exp(-log_inertia_hat))
    w_edge = wf - wf.min()
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.array([w_edge[0] / w_edge[1], w_edge[0] / w_edge[2]])
    edge = np.where(np.isnan(edge), 1.0, edge)
    ratio_range = np.sort(np.stack([edge, np.ones(2)], axis=1), axis=1)
    i_ref = 1 / wf
    alignment = float(abs(null @ i_ref) / np.linalg.norm(i_ref))
    return FitResult(
        inertia=1 / wg, inertia_ratios=out[:2], ratio_std=np.sqrt(var[:2]),
        inverse_differences=d, inverse_differences_std=np.sqrt(var[2:4]),
        m0=np.asarray(m0_hat), loss=float(final), noise_sigma=math.sqrt(sigma2),
        iterations=int(adam_steps) + int(iters), gauge=gauge, ratio_range=ratio_range,
        null_direction=null, null_alignment=alignment, hessian_eigenvalues=evals,
        seconds=time.perf_counter() - t0)


def simulate_observations(inertia, m0, t, noise: float, *, seed: int = 0, scheme="kahan-li-8",
                          max_step: float = 0.01):
    """Noisy observations m(t_k) + N(0, noise²) of a body with ``inertia`` (3,) from ``m0`` (3,) at
    times ``t`` (n,): a NumPy (n, 3) array (a test and notebook helper; reproducible from ``seed``).

    >>> import numpy as np, jaxsplit
    >>> jaxsplit.simulate_observations([2.0, 1.0, 0.5], [0.6, 0.0, 0.8], np.linspace(0, 1, 5), 1e-3).shape
    (5, 3)
    """
    t = np.asarray(t, dtype=float)
    inertia = np.asarray(inertia, dtype=float)
    dtype = jnp.result_type(float)
    n_sub = substeps(t, max_step)
    shift = int(np.argsort(1 / inertia, kind="stable")[1])
    clean = _predict_jit(schemes.resolve(scheme), shift, n_sub, jnp.log(jnp.asarray(inertia, dtype)),
                         jnp.asarray(m0, dtype), jnp.asarray(np.diff(t), dtype))
    rng = np.random.default_rng(seed)
    return np.asarray(clean) + noise * rng.standard_normal((len(t), 3))
