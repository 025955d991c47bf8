"""The one stepping loop: a fixed-step ``lax.scan`` (a scan of scans when saving).

``integrate`` is the jit boundary (``equinox.filter_jit``): the arrays inside ``step``
(its flows' parameters), the state and the step size are traced, so a new body, a new
``h`` or new initial conditions reuse compiled code; step counts and everything else in
``step`` are static. Python floats inside ``step`` are parameters too and are turned into
arrays before the boundary (else every value would compile anew). Any ``step(state, h)``
works; a ``Composition`` also merges sub-flows across step boundaries (``advance``).
"""

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import InputError
from ._state import as_state, float_dtype


class Trajectory(NamedTuple):
    """States saved every ``save_every`` steps (and the last one): ``x[i]`` at ``t[i]``."""

    t: jax.Array
    x: Any


def advance(step, x, h, n: int):
    """``n`` steps of ``step``; uses the step's own fused ``advance`` when it has one."""
    if hasattr(step, "advance"):
        return step.advance(x, h, n)
    if n == 0:
        return x
    return jax.lax.scan(lambda y, _: (step(y, h), None), x, length=n)[0]


def check_count(value, name: str, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


_TRACES = [0]


def compilations() -> int:
    """How many times ``integrate``'s loop has been traced (= compiled) in this process."""
    return _TRACES[0]


@eqx.filter_jit
def _run(step, x0, h, n_steps: int, save_every: int | None):
    _TRACES[0] += 1  # runs only while tracing
    if save_every is None:
        return advance(step, x0, h, n_steps)
    blocks, rest = divmod(n_steps, save_every)

    def block(x, _):
        x = advance(step, x, h, save_every)
        return x, x

    x, saved = jax.lax.scan(block, x0, length=blocks)
    pieces = [jax.tree_util.tree_map(lambda a: a[None], x0), saved]
    counts = [0] + [save_every * (k + 1) for k in range(blocks)]
    if rest:
        x = advance(step, x, h, rest)
        pieces.append(jax.tree_util.tree_map(lambda a: a[None], x))
        counts.append(n_steps)
    xs = jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *pieces)
    return Trajectory(jnp.asarray(counts, dtype=h.dtype) * h, xs)


def traced_parameters(step):
    """``step`` with its Python-float leaves as arrays (parameters are traced wherever they sit)."""
    return jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf) if type(leaf) is float else leaf, step)


def step_size(h, dtype):
    """``h`` as a finite real scalar of ``dtype`` (concrete values checked)."""
    if h is None or isinstance(h, (str, bytes, bool, np.bool_)) or jnp.iscomplexobj(h):
        raise InputError(f"h must be a real scalar step size, got {h!r}")
    try:
        h = jnp.asarray(h, dtype=dtype)
    except (TypeError, ValueError) as err:
        raise InputError(f"h must be a real scalar step size, got {h!r}") from err
    if h.ndim:
        raise InputError(f"h must be a scalar step size, got shape {h.shape}")
    if not isinstance(h, jax.core.Tracer) and not math.isfinite(float(h)):
        raise InputError(f"h must be finite, got {float(h)}")
    return h


def integrate(step, x0, h, n_steps: int, *, save_every: int | None = None):
    """Apply ``step(x, h)`` ``n_steps`` times from ``x0`` (any PyTree state).

    Returns the final state, or with ``save_every=k`` a ``Trajectory(t, x)`` holding the
    initial state, every k-th state and the final one (also when k does not divide
    ``n_steps``). A negative ``h`` integrates backwards. Works under ``jit``, ``vmap`` and
    ``grad``; the computation follows the dtype of ``x0``'s floating leaves (integer leaves
    are left alone; an all-integer state is promoted to the default float).
    """
    n_steps = check_count(n_steps, "n_steps", 0)
    if save_every is not None:
        save_every = check_count(save_every, "save_every", 1)
    if not callable(step):
        raise InputError(f"step must be callable as step(state, h), got {step!r}")
    x0 = as_state(x0)
    h = step_size(h, float_dtype(x0))
    step = traced_parameters(step)
    static = eqx.partition(step, eqx.is_array)[1]
    try:
        hash(static)
    except TypeError as err:
        raise InputError(f"step must be a function or a PyTree of arrays and hashable parts: {err}") from err
    return _run(step, x0, h, n_steps, save_every)


def integrate_checkpointed(step, x0, h, n_steps: int, *, block: int | None = None):
    """Final state after ``n_steps`` steps, for reverse-mode gradients with O(n/B + B) memory.

    The steps run as ⌊n/B⌋ blocks of B (default ⌈√n⌉) under ``jax.checkpoint`` plus the
    remainder; the forward values are those of ``integrate`` (same merged sub-flows).
    Not jitted: call it inside your own ``jit``/``grad``.
    """
    n_steps = check_count(n_steps, "n_steps", 0)
    if block is None:
        block = max(1, math.isqrt(max(n_steps, 1)))
    block = check_count(block, "block", 1)
    x0 = as_state(x0)
    h = step_size(h, float_dtype(x0))
    blocks, rest = divmod(n_steps, block)
    run_block = jax.checkpoint(lambda x: advance(step, x, h, block))
    x = jax.lax.scan(lambda y, _: (run_block(y), None), x0, length=blocks)[0] if blocks else x0
    return advance(step, x, h, rest) if rest else x
