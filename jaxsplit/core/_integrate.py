"""The one stepping loop: a fixed-step ``lax.scan`` (a scan of scans when saving).

``integrate`` is the jit boundary. ``step`` is split by its own PyTree flattening: the
modules declare their structure (static fields: axes, words, schemes, layouts) in the tree
definition, and every leaf that is an array or a Python float is a parameter, traced, so a
new body, a new ``h`` or new initial conditions reuse compiled code (a float counted as
static would compile anew for every value); the remaining leaves (functions, integers)
and the step counts are static. Any ``step(state, h)`` works; a ``Composition`` also
merges sub-flows across step boundaries (``advance``).
"""

import functools
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


MAX_COUNT = 2**53  # counts become the float times k*h: exact up to 2^53 (and beyond any run's reach)


def check_count(value, name: str, minimum: int) -> int:
    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer))
            or not minimum <= value <= MAX_COUNT):
        raise InputError(f"{name} must be an integer in [{minimum}, 2^53], got {value!r}")
    return int(value)


_TRACES = [0]


def compilations() -> int:
    """How many times ``integrate``'s loop has been traced (= compiled) in this process."""
    return _TRACES[0]


def _is_parameter(leaf) -> bool:
    return eqx.is_array(leaf) or type(leaf) is float


def split_parameters(step):
    """(parameters: the array and float leaves, static: (treedef, the other leaves))."""
    leaves, treedef = jax.tree_util.tree_flatten(step)
    parameters = [leaf if _is_parameter(leaf) else None for leaf in leaves]
    static = tuple(None if _is_parameter(leaf) else leaf for leaf in leaves)
    return parameters, (treedef, static)


def join_parameters(parameters, static):
    treedef, others = static
    return jax.tree_util.tree_unflatten(treedef, [p if s is None else s for p, s in zip(parameters, others)])


@functools.partial(jax.jit, static_argnames=("static", "n_steps", "save_every"))
def _run(parameters, static, x0, h, n_steps: int, save_every: int | None):
    _TRACES[0] += 1  # runs only while tracing
    step = join_parameters(parameters, static)
    h = jnp.asarray(h, dtype=float_dtype(x0))
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


def step_size(h):
    """``h`` checked: a real scalar, finite when concrete (cast to the state's dtype later)."""
    if isinstance(h, (int, float)) and not isinstance(h, bool):
        if not math.isfinite(h):
            raise InputError(f"h must be a finite step size, got {h!r}")
        return h
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
    if not isinstance(h, jax.core.Tracer) and not math.isfinite(float(value)):
        raise InputError(f"h must be a finite step size, got {float(value)}")
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
    parameters, static = split_parameters(step)
    try:
        hash(static)
    except TypeError as err:
        raise InputError(f"step must be a function or a PyTree of arrays and hashable parts: {err}") from err
    return _run(parameters, static, x0, step_size(h), n_steps, save_every)


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
    h = jnp.asarray(step_size(h), dtype=float_dtype(x0))
    blocks, rest = divmod(n_steps, block)
    run_block = jax.checkpoint(lambda x: advance(step, x, h, block))
    x = jax.lax.scan(lambda y, _: (run_block(y), None), x0, length=blocks)[0] if blocks else x0
    return advance(step, x, h, rest) if rest else x
