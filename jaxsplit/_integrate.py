"""The one stepping loop: a fixed-step ``lax.scan`` (a scan of scans when saving).

``integrate`` is the jit boundary. The step size is traced (a new ``h`` reuses compiled
code), the step counts are static. Any ``step(state, h)`` works; a ``Composition``
additionally merges sub-flows across step boundaries through its ``advance`` method.
"""

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import InputError


class Trajectory(NamedTuple):
    """States saved every ``save_every`` steps (and the last one): ``x[i]`` at ``t[i]``."""

    t: jax.Array
    x: Any


def _advance(step, x, h, n: int):
    """``n`` steps of ``step``; uses the step's own fused ``advance`` when it has one."""
    if hasattr(step, "advance"):
        return step.advance(x, h, n)
    if n == 0:
        return x
    return jax.lax.scan(lambda y, _: (step(y, h), None), x, length=n)[0]


def _check_count(value, name: str, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _float_state(x0):
    """Leaves as arrays of a floating dtype (integers promoted; floats kept as they are)."""

    def convert(leaf):
        arr = jnp.asarray(leaf)
        if not jnp.issubdtype(arr.dtype, jnp.inexact):
            arr = arr.astype(jnp.result_type(float))
        return arr

    return jax.tree_util.tree_map(convert, x0)


def _partition(tree):
    """Split a PyTree into array leaves (traced) and everything else (static, hashable)."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    is_array = tuple(isinstance(leaf, (jax.Array, np.ndarray)) for leaf in leaves)
    dynamic = [leaf for leaf, a in zip(leaves, is_array) if a]
    static = tuple(leaf for leaf, a in zip(leaves, is_array) if not a)
    return dynamic, (treedef, is_array, static)


def _combine(dynamic, spec):
    treedef, is_array, static = spec
    dyn, sta = iter(dynamic), iter(static)
    return jax.tree_util.tree_unflatten(treedef, [next(dyn) if a else next(sta) for a in is_array])


@functools.partial(jax.jit, static_argnames=("spec", "n_steps", "save_every"))
def _run(dynamic, spec, x0, h, n_steps: int, save_every: int | None):
    step = _combine(dynamic, spec)
    if save_every is None:
        return _advance(step, x0, h, n_steps)
    blocks, rest = divmod(n_steps, save_every)

    def block(x, _):
        x = _advance(step, x, h, save_every)
        return x, x

    x, saved = jax.lax.scan(block, x0, length=blocks)
    pieces = [jax.tree_util.tree_map(lambda a: a[None], x0), saved]
    counts = [0] + [save_every * (k + 1) for k in range(blocks)]
    if rest:
        x = _advance(step, x, h, rest)
        pieces.append(jax.tree_util.tree_map(lambda a: a[None], x))
        counts.append(n_steps)
    xs = jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *pieces)
    return Trajectory(jnp.asarray(counts, dtype=h.dtype) * h, xs)


def integrate(step, x0, h, n_steps: int, *, save_every: int | None = None):
    """Apply ``step(x, h)`` ``n_steps`` times from ``x0``.

    Returns the final state, or with ``save_every=k`` a ``Trajectory(t, x)`` holding the
    initial state, every k-th state and the final one (also when k does not divide
    ``n_steps``). A negative ``h`` integrates backwards. Works under ``jit``, ``vmap`` and
    ``grad``; the computation follows the dtype of ``x0``.
    """
    n_steps = _check_count(n_steps, "n_steps", 0)
    if save_every is not None:
        save_every = _check_count(save_every, "save_every", 1)
    x0 = _float_state(x0)
    dtype = jnp.result_type(*jax.tree_util.tree_leaves(x0))
    h = jnp.asarray(h, dtype=dtype)
    if h.ndim:
        raise InputError(f"h must be a scalar step size, got shape {h.shape}")
    dynamic, spec = _partition(step)
    try:
        hash(spec)
    except TypeError as err:
        raise InputError(f"step must be a function or a PyTree of arrays and hashable parts: {err}") from err
    return _run(dynamic, spec, x0, h, n_steps, save_every)

