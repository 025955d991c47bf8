"""Empirical convergence order: global errors over a ladder of step counts, log-log fit.

``global_errors`` compiles ONE integration for the whole ladder: every step size (traced) runs
the largest step count with every state saved, and the state at ``t_end`` is picked for each
(a new step count would otherwise mean a new compilation). The step sizes run in a loop, not
under ``vmap``: batching an unrolled high-order scheme costs more to trace than the runs cost.
``fit_order`` fits log(error) = p log(h) + c over the points in the asymptotic regime:
error inside a fixed window (above round-off, below the pre-asymptotic regime) and,
optionally, step sizes below ``max_step`` (for compositions with large weights the
asymptotic regime is set by the largest sub-step |w| h, not by the error).
"""

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._bounds import count, fits
from ..core._errors import InputError
from ..core._flows import join_parameters, split_parameters
from ..core._integrate import integrate
from ..core._state import as_state, float_dtype, is_floating

ORDER_WINDOW = (1e-13, 1e-4)  # ~10x the float64 round-off floor seen at T = 10 (1e-14)


class OrderFit(NamedTuple):
    """A fitted order: ``order`` (float), ``step_sizes`` and ``errors`` (NumPy (L,), float64)
    and ``used`` (bool (L,): the points inside the fit window).

    >>> import jaxsplit
    >>> fit = jaxsplit.fit_order([0.1, 0.05, 0.025], [1e-5, 2.5e-6, 6.25e-7])
    >>> round(fit.order, 6), fit.used.tolist()
    (2.0, [True, True, True])
    """

    order: float
    step_sizes: np.ndarray
    errors: np.ndarray
    used: np.ndarray  # mask of the points inside the window


def fit_order(step_sizes, errors, window=ORDER_WINDOW, max_step: float = np.inf,
              min_points: int = 3) -> OrderFit:
    """Least-squares slope of log(error) against log(h) over points with error in ``window``
    and |h| <= ``max_step``: an ``OrderFit``. Plain NumPy (concrete values, not traced);
    fewer than ``min_points`` usable points raise an ``InputError``.

    >>> import jaxsplit
    >>> round(jaxsplit.fit_order([0.2, 0.1, 0.05, 0.025], [1.6e-5, 1e-6, 6.25e-8, 3.90625e-9]).order, 2)
    4.0
    >>> jaxsplit.fit_order([0.2, 0.1, 0.05], [1e-2, 6e-4, 3.75e-5])    # pre-asymptotic: refused
    Traceback (most recent call last):
    ...
    jaxsplit.InputError: only 1 points lie in the fit window (1e-13, 0.0001), h <= inf (need 3): ...
    """
    h = np.abs(np.asarray(step_sizes, dtype=float))
    e = np.asarray(errors, dtype=float)
    used = np.isfinite(e) & (e >= window[0]) & (e <= window[1]) & (h <= max_step)
    if used.sum() < min_points:
        raise InputError(
            f"only {int(used.sum())} points lie in the fit window {window}, h <= {max_step:g} "
            f"(need {min_points}): "
            f"errors were {np.array2string(e, formatter={'float_kind': lambda v: f'{v:.2e}'})}; "
            "choose other step counts"
        )
    slope = np.polyfit(np.log(h[used]), np.log(e[used]), 1)[0]
    return OrderFit(float(slope), h, e, used)


def global_errors(step, x0, t_end: float, counts, reference):
    """(step sizes, max-norm errors at ``t_end``) for each step count in ``counts``.

    One compilation for the whole ladder (module docstring). ``x0`` and ``reference`` are
    PyTrees of the same structure; returns two NumPy arrays of shape (len(counts),) in the
    state's dtype, sorted by increasing count.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 2.0, 1.0])                          # symmetric: exact solution
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> step = jaxsplit.splitting(body, "strang", "axes")
    >>> hs, errors = jaxsplit.global_errors(step, m0, 1.0, [10, 20], jaxsplit.symmetric_solution(body, m0, 1.0))
    >>> hs.tolist(), bool(3.9 < errors[0] / errors[1] < 4.1)              # second order
    ([0.1, 0.05], True)
    """
    counts = np.asarray(sorted(int(n) for n in counts))
    if counts[0] < 1:
        raise InputError(f"step counts must be >= 1, got {counts.tolist()}")
    x0 = as_state(x0)
    hs = jnp.asarray(t_end / counts, dtype=float_dtype(x0))
    parameters, static = split_parameters(step)
    runs = [_saved_run(parameters, static, x0, h, int(counts[-1])) for h in hs]
    finals = jax.tree_util.tree_map(lambda *a: jnp.stack([r[n] for r, n in zip(a, counts)]), *runs)
    diffs = jax.tree_util.tree_map(lambda a, r: jnp.abs(a - r).reshape(len(counts), -1), finals, reference)
    floating = [d for d, a in zip(jax.tree_util.tree_leaves(diffs), jax.tree_util.tree_leaves(finals))
                if is_floating(a)]  # integer leaves ride along: not errors
    errors = jnp.max(jnp.concatenate(floating, axis=1), axis=1)
    return np.asarray(hs), np.asarray(errors)


@functools.partial(jax.jit, static_argnames=("static", "n_steps"))
def _saved_run(parameters, static, x0, h, n_steps: int):
    """Every state of ``n_steps`` steps; ``h`` is traced here, so one compilation serves the
    ladder, and any other ladder of the same scheme and length (body and state are traced too)."""
    return integrate(join_parameters(parameters, static), x0, h, n_steps, save_every=1).x


def ladder(start: int, factor: float = 16.0, points: int = 12):
    """``points`` step counts growing geometrically from ``start`` by ``factor`` overall
    (rounded, duplicates dropped, sorted): the ladder for ``estimate_order``.

    >>> import jaxsplit
    >>> jaxsplit.ladder(10, 8.0, 4)
    [10, 20, 40, 80]
    """
    start, points = count(start, "start"), count(points, "points", 2)
    if isinstance(factor, bool) or not isinstance(factor, (int, float)) or not (math.isfinite(factor) and factor > 1):
        raise InputError(f"factor must be a finite number > 1, got {factor!r}")
    fits(points * 64, f"a ladder of {points:,} step counts", "give fewer points")
    return sorted({round(start * factor ** (k / (points - 1))) for k in range(points)})


def estimate_order(step, x0, t_end: float, counts, reference=None, *, reference_step=None,
                   reference_count: int | None = None, window=ORDER_WINDOW) -> OrderFit:
    """Empirical order of ``step`` at ``t_end`` over the step-count ladder ``counts`` (any PyTree state).

    ``reference`` is the exact state at ``t_end`` (an array or PyTree), or a callable
    ``reference(t_end)`` (an exact solution), or ``None``: then a tight reference
    integration is made with ``reference_step`` (default: ``step`` itself) and
    ``reference_count`` steps (default: 16 × the largest count; pass a higher-order
    ``reference_step`` when ``step`` is of low order). The errors are max-norm global
    errors (``global_errors``, one compile) and the order is their log-log slope inside
    ``window`` (``fit_order``). ``t_end`` is traced, ``counts`` static.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.STANDARD_CASE.body()
    >>> step = jaxsplit.splitting(body, "suzuki-5", "casimir", shift=1)
    >>> fit = jaxsplit.estimate_order(step, jnp.array(jaxsplit.STANDARD_CASE.m0), 10.0, jaxsplit.ladder(40, 4.0, 4),
    ...                               jnp.array(jaxsplit.STANDARD_CASE.reference))
    >>> round(fit.order)
    4
    """
    if reference is None:
        reference_step = step if reference_step is None else reference_step
        n_ref = 16 * max(int(n) for n in counts) if reference_count is None else int(reference_count)
        if n_ref < 1:
            raise InputError(f"reference_count must be >= 1, got {reference_count!r}")
        x0 = as_state(x0)
        reference = integrate(reference_step, x0, jnp.asarray(t_end / n_ref, dtype=float_dtype(x0)), n_ref).final
    elif callable(reference):
        reference = reference(t_end)
    hs, errors = global_errors(step, x0, t_end, counts, reference)
    return fit_order(hs, errors, window)
