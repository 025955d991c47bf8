"""Fitting a system's parameters to an observed trajectory, by differentiating through the
integrator (any system of the system layer).

Model: ``family(params)`` (or ``family(params, fixed)``) is a system; from x0 the scheme on
its split runs ⌈Δt / max_step⌉ steps per observation interval; ``observe(x)`` (default: the
whole state) is compared with the data, or ``measure(states)``, a function of the whole
predicted trajectory (a spin lattice's S(q, ω): ``_fit_spins``). What reverse mode stores
(``adjoint``): ``"checkpoint"`` (default) runs each interval under ``jax.checkpoint``, so it
keeps one state per observation and, while differentiating an interval, its steps;
``"reversible"`` runs each interval through ``integrate``'s reversible adjoint
(``core._adjoints``), which rebuilds the interval's states by stepping back: one state per
observation, memory flat in the steps per interval (``benchmarks/results/fit_spins.md``).
The misfit is the mean squared residual over every observed component; Adam, then L-BFGS
(``_minimise``: one loop that evaluates the loss and gradient at one place) minimise it,
compiled once per configuration and data shape. The Gauss–Newton curvature JᵀJ of the
residuals at the optimum gives the standard deviations (σ̂² (JᵀJ)⁻¹, σ̂² = RSS / (N − p)) and,
through its eigenvalues and null vectors, what the data cannot determine.
"""

import dataclasses
import math
import time
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from .._bounds import count
from ..core._adjoints import advance, check_adjoint
from ..core._compose import roll
from ..core._errors import InputError
from ..core._schemes import schemes
from ..core._state import as_state, float_dtype, leading_size
from ..systems._splitting import splitting
from ._batch import family_of, ravel_rows
from ._minimise import minimise

# ------------------------------------------------------------------ the model
MAX_SUBSTEPS = 2**31 - 1  # lax.fori_loop counts an interval's model steps in int32


MAX_ITERATIONS = 2**31 - 1  # the optimisers count their iterations in int32 (also without x64)


def positive(value, name: str, zero: bool = False) -> float:
    """A finite real number > 0 (>= 0 with ``zero``)."""
    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating))
            or not math.isfinite(value) or not (value >= 0 if zero else value > 0)):
        raise InputError(f"{name} must be a finite number {'>= 0' if zero else '> 0'}, got {value!r}")
    return float(value)


def substeps(t, max_step) -> int:
    """⌈max Δt / max_step⌉ model steps per observation interval: at least 1, at most
    ``MAX_SUBSTEPS`` (more would wrap the loop counter), checked before anything compiles."""
    if isinstance(max_step, bool) or not (isinstance(max_step, (int, float, np.floating, np.integer))
                                          and math.isfinite(max_step) and max_step > 0):
        raise InputError(f"max_step must be a positive number, got {max_step!r}")
    longest = float(np.max(np.diff(t)))
    n = longest / float(max_step)
    if not n <= MAX_SUBSTEPS:
        raise InputError(f"max_step {max_step:g} needs {n:.3g} model steps for the longest observation interval "
                         f"({longest:g}), more than {MAX_SUBSTEPS:,}; use a larger max_step")
    return max(1, math.ceil(n))


ADJOINTS = ("checkpoint", "reversible")


def predict(family, params, x0, dts, *, scheme, split=None, options=(), n_sub: int = 1, fixed=None,
            adjoint: str = "checkpoint"):
    """The states at t0 and after every interval of ``dts`` (leading axis len(dts) + 1);
    ``adjoint`` as in the module docstring."""
    system = family(params) if fixed is None else family(params, fixed)
    if adjoint == "reversible":  # the unrolled Composition: what the reversible adjoint walks back
        step = splitting(system, scheme, split, **dict(options))
        check_adjoint("reversible", step)

        def interval(x, dt):
            x = advance(step, x, dt / n_sub, n_sub, "reversible")
            return x, x
    else:
        step = roll(splitting(system, scheme, split, **dict(options)))

        @jax.checkpoint
        def interval(x, dt):
            h = dt / n_sub
            x = jax.lax.fori_loop(0, n_sub, lambda _, y: step(y, h), x)
            return x, x

    later = jax.lax.scan(interval, x0, dts)[1]
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), x0, later)


# ------------------------------------------------------------------ the generic fit
class Model(eqx.Module):
    """The static description of a fit (hashable: one compilation per model and data shape)."""

    family: Any = eqx.field(static=True)
    scheme: Any = eqx.field(static=True)
    split: Any = eqx.field(static=True)
    options: tuple = eqx.field(static=True)
    n_sub: int = eqx.field(static=True)
    fit_x0: bool = eqx.field(static=True)
    observe: Any = eqx.field(static=True)
    measure: Any = eqx.field(static=True, default=None)
    adjoint: str = eqx.field(static=True, default="checkpoint")

    def residuals(self, theta, data):
        params, x0 = theta["params"], (theta["x0"] if self.fit_x0 else data["x0"])
        states = predict(self.family, params, x0, data["dts"], scheme=self.scheme, split=self.split,
                         options=self.options, n_sub=self.n_sub, fixed=data["fixed"], adjoint=self.adjoint)
        if self.measure is not None:
            return (jnp.reshape(self.measure(states), (-1,)) - data["observed"]).reshape(-1)
        seen = jax.vmap(self.observe)(states) if self.observe is not None else states
        flat = jnp.concatenate([jnp.reshape(a, (a.shape[0], -1)) for a in jax.tree_util.tree_leaves(seen)], axis=1)
        return (flat - data["observed"]).reshape(-1)


@eqx.filter_jit
def _optimise(model, theta, data, adam_steps: int, adam_lr: float, lbfgs_iter: int, tol: float):
    return minimise(lambda p: model.residuals(p, data), theta, adam_steps, adam_lr, lbfgs_iter, tol)


@eqx.filter_jit
def _curvature(model, theta, data):
    # forward mode (p passes for p parameters): the reversible adjoint has no JVP, and the
    # checkpointed model computes the same values (forward mode stores nothing either way)
    model = dataclasses.replace(model, adjoint="checkpoint")
    flat, unravel = jax.flatten_util.ravel_pytree(theta)
    jac = jax.jacfwd(lambda f: model.residuals(unravel(f), data))(flat)
    r = model.residuals(theta, data)
    return jac, jnp.sum(r * r)


class ParameterFit(NamedTuple):
    """Outcome of ``fit``: estimates, their Gauss–Newton standard deviations, diagnostics.

    ``params``, ``params_std`` (NumPy leaves, the PyTree of ``params0``), ``x0``, ``loss`` and
    ``noise_sigma`` (floats), ``covariance`` (P, P) over the flattened fitted values,
    ``hessian_eigenvalues`` (P,) ascending with ``null_directions`` (P, P) as columns (near-0
    eigenvalues: what the data do not fix), ``iterations``, ``seconds``. Concrete values.
    See ``fit`` for a run.

    >>> import jaxsplit
    >>> jaxsplit.ParameterFit._fields[:5]
    ('params', 'params_std', 'x0', 'loss', 'noise_sigma')
    """

    params: Any  # the fitted parameters (same PyTree as params0)
    params_std: Any  # their standard deviations (same PyTree)
    x0: Any  # the fitted (or given) initial state
    loss: float  # final mean squared misfit per observed component
    noise_sigma: float  # σ̂ from the residuals
    covariance: np.ndarray  # over the flattened (params, x0) when fitted
    hessian_eigenvalues: np.ndarray  # of JᵀJ (ascending): near-0 ones are what the data do not fix
    null_directions: np.ndarray  # eigenvectors (columns) of JᵀJ, same order
    iterations: int
    seconds: float


def _observations(t, observed):
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError) as err:
        raise InputError(f"t must be numeric times, got {t!r}") from err
    if t.ndim != 1 or len(t) < 2:
        raise InputError(f"t must have shape (n,) with n >= 2, got shape {t.shape}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputError("t must be finite and strictly increasing")
    observed = as_state(observed, "observed")
    if leading_size(observed, "observed") != len(t):
        raise InputError(f"observed must have one entry per time ({len(t)}) along its leading axis")
    rows = ravel_rows(observed)
    if not np.all(np.isfinite(rows)):
        raise InputError("observed must be finite (no NaN or inf)")
    return t, rows


def fit(family, t, observed, params0, *, x0=None, fit_x0: bool = True, fixed=None, observe=None, measure=None,
        scheme="kahan-li-6", split=None, max_step: float = 0.05, adjoint: str = "checkpoint", adam_steps: int = 50,
        adam_lr: float = 3e-4, lbfgs_iter: int = 200, tol: float = 1e-10, **split_options) -> ParameterFit:
    """Fit ``params`` of the system ``family(params)`` (``family(params, fixed)`` with
    ``fixed``) to states ``observed`` (a PyTree with a leading axis n) at times ``t`` (n,).

    ``params0`` is the starting point (any PyTree of floats; parametrise positive quantities
    by their logarithm in ``family``). ``x0`` is the initial state (default: the first
    observation, which needs ``observe=None``), fitted too unless ``fit_x0=False``.
    ``observe(x)`` maps a state to what was observed; ``measure(states)`` instead maps the
    whole predicted trajectory (leading axis n) to what was observed (then ``observed`` is
    that array, of any shape, and ``x0`` is needed). The model integrates ``scheme`` on
    ``split`` (with ``split_options``) with ⌈Δt / max_step⌉ steps per interval; ``adjoint``
    ("checkpoint" or "reversible", module docstring) is what its gradient stores. optax Adam
    (``adam_steps``), then L-BFGS (``lbfgs_iter``, ``_minimise``), on the mean squared misfit; one
    compilation per model and data shape (the parameters and data are traced inside it).
    Returns a ``ParameterFit`` (concrete NumPy values) in the dtype of ``x0``.

    >>> import jax.numpy as jnp, numpy as np, jaxsplit
    >>> family = lambda log_inertia: jaxsplit.RigidBody(jnp.exp(log_inertia), allow_nonphysical=True)
    >>> t, m0 = np.linspace(0.0, 2.0, 9), jnp.array([0.6, 0.0, 0.8])
    >>> observed = jaxsplit.simulate(family, jnp.log(jnp.array([2.0, 1.0, 0.5])), m0, t, split="casimir", shift=1)
    >>> f = jaxsplit.fit(family, t, observed, jnp.log(jnp.array([2.0, 1.1, 0.5])), x0=m0, fit_x0=False,
    ...                  split="casimir", shift=1, max_step=0.25, adam_steps=0, lbfgs_iter=30)
    >>> f.loss < 1e-12, np.round(1 / np.exp(f.params[:2]) - 1 / np.exp(f.params[2]), 6).tolist()
    (True, [-1.5, -1.0])

    Only the differences 1/I_i − 1/I_j are fixed by m(t) (H and H + c C have the same flow): the
    smallest Hessian eigenvalue (``f.hessian_eigenvalues[0]``) is near 0 along that direction.
    """
    start = time.perf_counter()
    family = family_of(family)
    scheme = schemes.resolve(scheme)
    adam_steps = count(adam_steps, "adam_steps", 0, MAX_ITERATIONS - 1, "Adam's steps are counted in int32")
    lbfgs_iter = count(lbfgs_iter, "lbfgs_iter", 0, MAX_ITERATIONS, "L-BFGS counts its iterations in int32")
    adam_lr, tol = positive(adam_lr, "adam_lr"), positive(tol, "tol", zero=True)
    if adjoint not in ADJOINTS:
        raise InputError(f"adjoint must be one of {ADJOINTS}, got {adjoint!r}")
    if measure is not None:
        if observe is not None:
            raise InputError("give observe= (per state) or measure= (of the whole trajectory), not both")
        t, _ = _observations(t, np.zeros((len(np.atleast_1d(t)), 1)))
        rows = np.asarray(observed, dtype=float).reshape(-1)
        if not np.all(np.isfinite(rows)):
            raise InputError("observed must be finite (no NaN or inf)")
    else:
        t, rows = _observations(t, observed)
    n_sub = substeps(t, max_step)
    if x0 is None:
        if observe is not None or measure is not None:
            raise InputError("give x0= when only part of the state is observed (observe=... or measure=...)")
        x0 = jax.tree_util.tree_map(lambda a: a[0], as_state(observed, "observed"))
    x0 = as_state(x0, "x0")
    dtype = float_dtype(x0)
    params0 = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), params0)
    system = family(params0) if fixed is None else family(params0, fixed)
    split, options = system.resolve_split(split, **split_options)
    model = Model(family, scheme, split, tuple(sorted(options.items())), n_sub, bool(fit_x0), observe, measure,
                  adjoint)
    data = {"x0": x0, "dts": jnp.asarray(np.diff(t), dtype), "observed": jnp.asarray(rows, dtype),
            "fixed": None if fixed is None else jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), fixed)}
    theta = {"params": params0, "x0": x0 if fit_x0 else None}
    theta, iters, final = _optimise(model, theta, data, int(adam_steps), float(adam_lr), int(lbfgs_iter), float(tol))
    jac, rss = (np.asarray(a) for a in _curvature(model, theta, data))
    n_res, n_par = jac.shape
    sigma2 = float(rss) / max(n_res - n_par, 1)
    gram = jac.T @ jac
    cov = sigma2 * np.linalg.pinv(gram)
    evals, evecs = np.linalg.eigh(gram)
    _, unravel = jax.flatten_util.ravel_pytree(theta)
    std = unravel(jnp.asarray(np.sqrt(np.maximum(np.diag(cov), 0))))
    to_np = lambda tree: jax.tree_util.tree_map(np.asarray, tree)
    return ParameterFit(to_np(theta["params"]), to_np(std["params"]), to_np(theta["x0"] if fit_x0 else x0),
                        float(final), math.sqrt(sigma2), cov, evals, evecs, int(adam_steps) + int(iters),
                        time.perf_counter() - start)


def simulate(family, params, x0, t, *, fixed=None, observe=None, noise: float = 0.0, seed: int = 0,
             scheme="kahan-li-8", split=None, max_step: float = 0.01, **split_options):
    """States (or ``observe(x)``) of ``family(params)`` at times ``t`` (n,) plus N(0, noise²) noise:
    synthetic observations for tests, notebooks and benchmarks. NumPy leaves with a leading
    axis n (the first row is x0), in the dtype of ``x0``; ``scheme`` (8th order) with
    ⌈Δt / max_step⌉ steps per interval; reproducible from ``seed``.

    >>> import jax.numpy as jnp, numpy as np, jaxsplit
    >>> family = lambda log_inertia: jaxsplit.RigidBody(jnp.exp(log_inertia), allow_nonphysical=True)
    >>> t, m0 = np.linspace(0.0, 2.0, 9), jnp.array([0.6, 0.0, 0.8])
    >>> observed = jaxsplit.simulate(family, jnp.log(jnp.array([2.0, 1.0, 0.5])), m0, t, split="casimir", shift=1)
    >>> observed.shape, bool(np.allclose(observed[0], m0))
    ((9, 3), True)
    """
    t, _ = _observations(t, np.zeros((len(np.atleast_1d(t)), 1)))
    noise = positive(noise, "noise", zero=True)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    x0 = as_state(x0, "x0")
    dtype = float_dtype(x0)
    params = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), params)
    system = family(params) if fixed is None else family(params, fixed)
    split, options = system.resolve_split(split, **split_options)
    n_sub = substeps(t, max_step)
    states = jax.jit(predict, static_argnums=(0,), static_argnames=("scheme", "split", "options", "n_sub"))(
        family, params, x0, jnp.asarray(np.diff(t), dtype), scheme=schemes.resolve(scheme), split=split,
        options=tuple(sorted(options.items())), n_sub=n_sub, fixed=fixed)
    seen = jax.vmap(observe)(states) if observe is not None else states
    rng = np.random.default_rng(seed)
    return jax.tree_util.tree_map(lambda a: np.asarray(a) + noise * rng.standard_normal(np.shape(a)), seen)
