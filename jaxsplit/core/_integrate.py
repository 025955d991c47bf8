"""The one stepping loop, the jit boundary, and its result.

``integrate`` advances ``step`` with a fixed step size by a ``lax.scan`` (a scan of scans
when saving every k-th state) and returns one result type, ``Solution``: the saved times
and states (always the initial and the final one), the final state one attribute away,
the step count, the step size, the scheme, and whether every state stayed finite.

Output at arbitrary times (``ts=``): each requested state is a *partial step* of the scheme
from the last grid state before it, Ψ_δ(x_k) with δ = t − t_k, so it is the image of a
Poisson map of the same scheme (Casimirs to round-off, the scheme's accuracy), not an
interpolant that leaves the symplectic leaf. The grid is advanced with traced step counts,
so a new set of times of the same length reuses the compiled code.

``integrate`` is the jit boundary. ``step`` is split by its own PyTree flattening: the
modules declare their structure (static fields: axes, words, schemes, layouts) in the tree
definition, and every leaf that is an array or a Python float is a parameter, traced, so a
new body, a new ``h`` or new initial conditions reuse compiled code (a float counted as
static would compile anew for every value); the remaining leaves (functions, integers)
and the step counts are static. Any ``step(state, h)`` works; a ``Composition`` also
merges sub-flows across step boundaries. ``adjoint`` chooses what reverse mode stores
(``_adjoints``).
"""

import functools
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _bounds
from ._adjoints import advance, advance_checkpointed, choose_adjoint, stored_engine
from ._errors import InputError
from ._flows import check_state, join_parameters, split_parameters
from ._state import as_state, float_dtype


class Solution(eqx.Module):
    """The result of ``integrate``: states ``x[i]`` (any PyTree, leading axis K) at times ``t[i]``.

    Shapes and dtypes: ``t`` (K,) and ``h`` () in the state's floating dtype; every leaf of
    ``x`` is the state's leaf with a leading axis K (K = 2 without saving: initial and final);
    ``finite`` a bool scalar. ``final`` is the last saved state (the end of the run, or the
    last requested time); ``n_steps`` the full steps taken (static; ``None`` for ``ts=`` runs),
    ``scheme`` the scheme's name (static; ``None`` for a plain function), ``status`` is
    ``"ok"`` / ``"nonfinite"`` (needs concrete values). Under ``vmap`` every array field gains
    the batch axis. ``Trajectory`` is the former name.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)     # 1 + 0.5 < 2: on purpose
    >>> step = jaxsplit.splitting(body, "strang", "casimir", shift=1)
    >>> sol = jaxsplit.integrate(step, jnp.array([0.6, 0.0, 0.8]), 0.5, 4)
    >>> sol.t.tolist(), sol.x.shape, sol.final.shape, sol.n_steps, sol.scheme, sol.status
    ([0.0, 2.0], (2, 3), (3,), 4, 'strang', 'ok')
    """

    t: jax.Array
    x: Any
    h: jax.Array
    finite: jax.Array
    n_steps: int | None = eqx.field(static=True)
    scheme: str | None = eqx.field(static=True, default=None)

    @property
    def final(self):
        """The last saved state: the old return value of ``integrate`` without saving."""
        return _last(self.x)

    @property
    def status(self) -> str:
        return "ok" if bool(np.all(np.asarray(self.finite))) else "nonfinite"


Trajectory = Solution  # the former name of the saved-states result


@jax.jit  # compiled once per state structure: indexing each leaf eagerly took 65 µs a call
def _last(x):
    return jax.tree_util.tree_map(lambda a: a[-1], x)


MAX_GRID_STEPS = 2**31 - 1  # output times: the grid step before each time, an int32 index
MAX_COUNT = 2**53  # counts become the float times k*h: exact up to 2^53 (and beyond any run's reach)


def check_count(value, name: str, minimum: int) -> int:
    return _bounds.count(value, name, minimum)


_TRACES = [0]


def compilations() -> int:
    """How many times ``integrate``'s loop has been traced (= compiled) in this process."""
    return _TRACES[0]


def _finite(x):
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves(x)
                              if jnp.issubdtype(a.dtype, jnp.inexact)] or [jnp.asarray(True)]))


def _stack(*pieces):
    return jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *pieces)


def _one(x):
    return jax.tree_util.tree_map(lambda a: a[None], x)


@functools.partial(jax.jit, static_argnames=("static", "n_steps", "save_every", "adjoint"))
def _run(parameters, static, x0, h, t0, n_steps: int, save_every: int | None, adjoint: str):
    _TRACES[0] += 1  # runs only while tracing
    step = join_parameters(parameters, static)
    dtype = float_dtype(x0)
    h, t0 = jnp.asarray(h, dtype=dtype), jnp.asarray(t0, dtype=dtype)
    if save_every is None:
        x = advance(step, x0, h, n_steps, adjoint)
        xs, counts = _stack(_one(x0), _one(x)), [0, n_steps]
    else:
        blocks, rest = divmod(n_steps, save_every)

        def block(x, _):
            x = advance(step, x, h, save_every, adjoint)
            return x, x

        x, saved = jax.lax.scan(block, x0, length=blocks)
        pieces = [_one(x0), saved]
        counts = [0] + [save_every * (k + 1) for k in range(blocks)]
        if rest:
            x = advance(step, x, h, rest, adjoint)
            pieces.append(_one(x))
            counts.append(n_steps)
        xs = _stack(*pieces)
    t = t0 + jnp.asarray(counts, dtype=dtype) * h
    return Solution(t, xs, h, _finite(xs), n_steps, _scheme_name(step))


@functools.partial(jax.jit, static_argnames=("static", "adjoint"))
def _run_at(parameters, static, x0, h, t0, ts, adjoint: str):
    """States at the times ``ts``: full grid steps, then a partial step from the grid state."""
    _TRACES[0] += 1
    step = join_parameters(parameters, static)
    dtype = float_dtype(x0)
    h, t0, ts = jnp.asarray(h, dtype=dtype), jnp.asarray(t0, dtype=dtype), jnp.asarray(ts, dtype=dtype)
    grid = jnp.maximum(jnp.floor((ts - t0) / h), 0).astype(jnp.int32)  # last grid point at or before t

    def output(carry, i):
        x, k = carry
        x = advance(step, x, h, grid[i] - k, adjoint)
        return (x, grid[i]), step(x, ts[i] - (t0 + grid[i] * h))

    _, xs = jax.lax.scan(output, (x0, jnp.zeros((), jnp.int32)), jnp.arange(ts.shape[0]))
    return Solution(ts, xs, h, _finite(xs), None, _scheme_name(step))


def _scheme_name(step):
    scheme = getattr(step, "scheme", None)
    return getattr(scheme, "name", None)


def step_size(h, nonzero: bool = False):
    """``h`` checked: a real scalar, finite (and non-zero when ``nonzero``: a run of steps of
    length 0 goes nowhere) when concrete (cast to the state's dtype later)."""
    if isinstance(h, (int, float)) and not isinstance(h, bool):
        value = h
    else:
        if h is None or isinstance(h, (str, bytes, bool, np.bool_)):
            raise InputError(f"h must be a real scalar step size, got {h!r}")
        if isinstance(h, jax.core.Tracer):
            value = h
        else:
            try:
                value = np.asarray(h)
            except (TypeError, ValueError) as err:
                raise InputError(f"h must be a real scalar step size, got {h!r}") from err
        if value.ndim or not (jnp.issubdtype(value.dtype, jnp.floating) or jnp.issubdtype(value.dtype, jnp.integer)):
            raise InputError(f"h must be a real scalar step size, got {h!r}")
        if isinstance(h, jax.core.Tracer):
            return h
        value = float(value)
    if not math.isfinite(value):
        raise InputError(f"h must be a finite step size, got {value!r}")
    if nonzero and value == 0:
        raise InputError("h must be a non-zero step size (negative integrates backwards), got 0")
    return h


def initial_time(t0):
    """``t0`` checked: a real scalar, finite when concrete (a NaN start makes every time NaN)."""
    if type(t0) in (float, int):  # the common case, without NumPy
        if not math.isfinite(t0):
            raise InputError(f"t0 must be a finite time, got {t0}")
        return t0
    if t0 is None or isinstance(t0, (str, bytes, bool, np.bool_)):
        raise InputError(f"t0 must be a real number, got {t0!r}")
    if isinstance(t0, jax.core.Tracer):
        return t0
    try:
        value = np.asarray(t0)
    except (TypeError, ValueError) as err:
        raise InputError(f"t0 must be a real number, got {t0!r}") from err
    if value.ndim or not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
        raise InputError(f"t0 must be a real scalar time, got {t0!r}")
    if not math.isfinite(float(value)):
        raise InputError(f"t0 must be a finite time, got {float(value)}")
    return t0


# Below this many bytes of saved states no memory check is needed (it reads /proc/meminfo).
_SMALL_OUTPUT = 2**26


def _output_memory(n_saved: int, x0, hint: str):
    """Refuse a run whose saved states would not fit: their bytes, twice (the loop's output and
    the stacked result), against the memory available where x0 lives (under ``vmap`` an
    estimate without the batch axes)."""
    need = n_saved * _bounds.array_bytes(x0)
    if need <= _SMALL_OUTPUT:
        return
    leaf = next((a for a in jax.tree_util.tree_leaves(x0) if isinstance(a, jax.Array)
                 and not isinstance(a, jax.core.Tracer)), None)
    device = next(iter(leaf.devices())) if leaf is not None else jax.devices()[0]
    _bounds.fits(2 * need, f"the saved states ({n_saved:,} of {_bounds.format_bytes(need / n_saved)}, and a copy)",
                 hint, device)


def _output_times(ts, t0, h):
    """Concrete checks of ``ts``: a non-empty 1-D array of finite times, ordered in the
    direction of h and not before t0 (traced values pass unchecked)."""
    if any(isinstance(v, jax.core.Tracer) for v in (ts, t0, h)):
        return ts
    try:
        arr = np.asarray(ts)
    except (TypeError, ValueError) as err:
        raise InputError(f"ts must be a 1-D array of real output times, got {type(ts).__name__}") from err
    if np.iscomplexobj(arr):
        raise InputError(f"ts must be real times, got dtype {arr.dtype} (times are real; h and t0 too)")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InputError(f"ts must be real output times, got dtype {arr.dtype}")
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"ts must be a non-empty 1-D array of output times, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError("ts must be finite")
    direction = np.sign(float(np.asarray(h))) or 1.0
    ahead = np.diff(np.concatenate([[float(np.asarray(t0))], arr])) * direction
    if np.any(ahead < 0):
        raise InputError(f"ts must be ordered in the direction of h (h = {float(np.asarray(h)):g}) and start at or "
                         f"after t0 = {float(np.asarray(t0)):g}; got first time {arr[0]:g}")
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.abs((arr[-1] - float(np.asarray(t0))) / float(np.asarray(h)))
    if not steps <= MAX_GRID_STEPS:  # the grid index is an int32 (it must also run without x64)
        raise InputError(f"ts reaches {arr[-1]:g}, {steps:.3g} steps of h = {float(np.asarray(h)):g} from t0: at most "
                         f"2^31 - 1 steps are allowed; use a larger h or split the run")
    return ts


def integrate(step, x0, h, n_steps: int | None = None, *, save_every: int | None = None, ts=None,
              t0: float = 0.0, adjoint: str | None = None) -> Solution:
    """Advance ``x0`` (any PyTree state) by ``step(x, h)`` with a fixed step ``h``; a ``Solution``.

    * ``integrate(step, x0, h, n)``: ``n`` steps; ``.final`` is the state after them (the saved
      states are the initial and the final one).
    * ``save_every=k``: also every k-th state (the final one too when k does not divide n).
    * ``ts=times`` (instead of ``n``): the states at the given times, each a partial step of
      the scheme from the last grid state t0 + k h before it (see the module docstring).

    The compiled program does not depend on the values of ``x0``, ``h`` or the step's
    parameters, nor on whether this call sits under your own ``jit``, ``vmap`` or ``grad``:
    ``jax.jit(jax.vmap(lambda m: integrate(step, m, h, n).final))`` runs the same kernels as
    ``integrate(step, batch, h, n)``.
    A negative ``h`` integrates backwards. ``t0`` is the initial time. ``adjoint`` is
    ``"store"``, ``"checkpoint"`` or ``"reversible"`` (see ``jaxsplit.core._adjoints``); by
    default ``"store"``, except for a ``ts=`` run under reverse-mode differentiation (``grad``),
    which takes ``"reversible"`` (``choose_adjoint``: the only adjoint that differentiates
    its loops of traced length backwards).
    Works under ``jit``, ``vmap`` and ``grad``; the computation follows the dtype of
    ``x0``'s floating leaves (integer leaves are left alone; an all-integer state is
    promoted to the default float).

    Traced (new values reuse the compiled loop): ``x0``, ``h``, ``t0``, the values of ``ts``
    and every array or float leaf of ``step`` (a body's inertia). Static: ``n_steps``,
    ``save_every``, the length of ``ts``, ``adjoint`` and the structure of ``step``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)     # 1 + 0.5 < 2: on purpose
    >>> step = jaxsplit.splitting(body, "strang", "casimir")
    >>> sol = jaxsplit.integrate(step, jnp.array([0.6, 0.0, 0.8]), 0.1, 100, save_every=10)
    >>> sol.final.shape, sol.x.shape, float(sol.t[-1])
    ((3,), (11, 3), 10.0)
    """
    if not callable(step):
        raise InputError(f"step must be callable as step(state, h), got {step!r}")
    x0 = as_state(x0)
    h = step_size(h, nonzero=True)
    t0 = initial_time(t0)
    check_state(step, x0)  # what the step's flows accept (an attitude must be a rotation)
    parameters, static = split_parameters(step)
    try:
        hash(static)
    except TypeError as err:
        raise InputError(f"step must be a function or a PyTree of arrays and hashable parts: {err}") from err
    adjoint = choose_adjoint(adjoint, step, ts is not None, (parameters, x0, h, t0, ts))
    adjoint = stored_engine(adjoint, step, (parameters, x0, h, t0))
    if ts is not None:
        if n_steps is not None or save_every is not None:
            raise InputError("give either ts= (output times) or n_steps (with save_every=), not both")
        if adjoint == "checkpoint":
            raise InputError("adjoint='checkpoint' applies to n_steps runs; with ts= use 'store' or 'reversible'")
        ts = _output_times(ts, t0, h)
        _output_memory(int(np.shape(ts)[0]), x0, "give fewer output times")
        return _run_at(parameters, static, x0, h, t0, ts, adjoint)
    if n_steps is None:
        raise InputError("integrate needs n_steps (the number of steps) or ts= (output times)")
    n_steps = check_count(n_steps, "n_steps", 0)
    if save_every is not None:
        save_every = check_count(save_every, "save_every", 1)
        n_saved = n_steps // save_every + 2
        _output_memory(n_saved, x0, f"save fewer states, e.g. save_every={max(save_every + 1, n_steps // 1000)}")
    return _run(parameters, static, x0, h, t0, n_steps, save_every, adjoint)


def integrate_checkpointed(step, x0, h, n_steps: int, *, block: int | None = None):
    """Final state after ``n_steps`` steps, for reverse-mode gradients with O(n/B + B) memory.

    The steps run as ⌊n/B⌋ blocks of B (default ⌈√n⌉) under ``jax.checkpoint`` plus the
    remainder; the forward values are those of ``integrate`` (same merged sub-flows).
    Not jitted: call it inside your own ``jit``/``grad`` (or use ``integrate(...,
    adjoint="checkpoint")``). ``x0`` any PyTree (result: same structure and dtypes), ``h``
    traced, ``n_steps`` and ``block`` static.

    >>> import jax, jax.numpy as jnp, jaxsplit
    >>> def loss(inertia):
    ...     step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
    ...     return jaxsplit.integrate_checkpointed(step, jnp.array([0.6, 0.0, 0.8]), 0.1, 100)[0]
    >>> jax.jit(jax.grad(loss))(jnp.array([2.0, 1.0, 0.5])).shape
    (3,)
    """
    n_steps = check_count(n_steps, "n_steps", 0)
    if block is not None:
        block = check_count(block, "block", 1)
    x0 = as_state(x0)
    h = jnp.asarray(step_size(h, nonzero=True), dtype=float_dtype(x0))
    return advance_checkpointed(step, x0, h, n_steps, block)
