"""Long integrations in chunks of equal size: one compilation, a finite-state check and a
chance to stop after every chunk, and the first non-finite step found exactly.

``run_chunked`` saves like ``integrate(..., save_every=k)`` (x0, every k-th state, the
last one), and the states at requested times as partial steps from the chunk that holds
them (``integrate(ts=...)``). States are any PyTree (m, or (m, Q), (m, Γ)). It stops at the first non-finite state (keeping the last finite one) or when
``stop()`` turns true between chunks (the signal policy's ``requested``); either way the
states computed so far are returned, never lost.
"""

import time
from typing import NamedTuple

import numpy as np

TARGET_FLOWS_PER_CHUNK = 1_000_000  # ~0.05-0.4 s of work per chunk on a CPU core


class RunResult(NamedTuple):
    """Saved states of a chunked run: ``x[i]`` (a PyTree of NumPy arrays, leading axis) after
    ``steps[i]`` steps, and ``x_at[j]`` at the requested times ``t_at[j]`` reached."""

    steps: np.ndarray
    x: object
    completed: int  # steps completed with a finite state
    nonfinite_step: int | None  # first step whose state is not finite
    interrupted: bool
    seconds: float
    t_at: np.ndarray | None = None
    x_at: object = None


def chunk_size(n_steps: int, save_every: int, flows_per_step: int = 1,
               target_flows: int | None = None) -> int:
    """Steps per chunk doing about ``target_flows`` flows: a multiple of ``save_every`` when
    states are saved that often, else a plain step count (saves then fall on chunk ends)."""
    target_flows = TARGET_FLOWS_PER_CHUNK if target_flows is None else target_flows
    per = max(1, target_flows // max(1, flows_per_step))
    if save_every > per:
        return min(per, n_steps)
    chunk = (per // save_every) * save_every
    return min(chunk, max(save_every, -(-n_steps // save_every) * save_every))


# ---- states are PyTrees (m, or (m, Q), ...): rows along the leading axis
def host(tree):
    import jax

    return jax.tree_util.tree_map(np.asarray, tree)


def rows(tree, index):
    import jax

    return jax.tree_util.tree_map(lambda a: a[index], tree)


def concatenate(trees):
    import jax

    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *trees)


def _one(tree):
    import jax

    return jax.tree_util.tree_map(lambda a: np.asarray(a)[None], tree)


def _finite_rows(tree) -> np.ndarray:
    import jax

    leaves = jax.tree_util.tree_leaves(tree)
    n = len(leaves[0])
    ok = np.ones(n, bool)
    for a in leaves:
        ok &= np.all(np.isfinite(np.asarray(a).reshape(n, -1)), axis=1) if n else ok
    return ok


def first_nonfinite(step, x, h, n: int):
    """Within ``n`` steps from the finite state ``x``: (first step k >= 1 whose state is not
    finite, the state after k - 1 steps). Narrows down by blocks, 1024 saves at a time."""
    from ..core._integrate import integrate

    offset = 0
    while True:
        block = max(1, -(-n // 1024))
        traj = integrate(step, x, h, n, save_every=block)
        xs = host(traj.x)
        counts = np.minimum(np.arange(len(traj.t)) * block, n)
        bad = np.flatnonzero(~_finite_rows(xs))
        if len(bad) == 0:  # round-off differences between runs: treat the last step as bad
            return offset + n, rows(xs, -1)
        i = int(bad[0])
        if block == 1:
            return offset + int(counts[i]), rows(xs, i - 1)
        offset += int(counts[i - 1])
        n = int(counts[i] - counts[i - 1])
        x = rows(traj.x, i - 1)


def _states_at(step, x, h, times, first_step: int):
    """States at ``times`` (all within the chunk starting at step ``first_step`` from ``x``),
    each a partial step from the grid; the count is padded to a power of two so a run compiles
    O(log) shapes, not one per chunk."""
    from ..core._integrate import integrate

    k = len(times)
    t0 = first_step * h  # a time that rounds to just before the chunk's start is taken at it
    times = np.maximum(times, t0) if h > 0 else np.minimum(times, t0)
    padded = np.concatenate([times, np.full((1 << max(0, k - 1).bit_length()) - k, times[-1])])
    sol = integrate(step, x, h, ts=padded, t0=t0)
    return rows(host(sol.x), slice(0, k))


def run_chunked(step, x0, h, n_steps: int, save_every: int, *, flows_per_step: int = 1,
                chunk: int | None = None, progress=None, stop=None, at=None) -> RunResult:
    """Integrate in chunks of equal size (the compiled scan is reused), checking after each
    chunk that the state is finite. Saves ``x0``, every ``save_every``-th state and the last
    one, like ``integrate(..., save_every=...)``, and the states at the times ``at`` (sorted
    in the direction of ``h``, within the run), each a partial step of the scheme
    (``integrate(ts=...)``). A non-finite state stops the run at the first bad step;
    ``stop()`` turning true stops it after the current chunk; either way the states computed
    so far are returned (with the last good state). ``x0`` is any PyTree state."""
    import jax.numpy as jnp

    from ..core._integrate import integrate

    chunk = chunk or chunk_size(n_steps, save_every, flows_per_step)
    aligned = chunk % save_every == 0  # else save_every > chunk: saves fall on chunk ends
    start = time.perf_counter()
    x = jnp.asarray(x0) if not isinstance(x0, tuple) else x0
    steps, saved = [np.zeros(1, dtype=np.int64)], [_one(host(x))]
    at = None if at is None else np.asarray(at, dtype=np.float64)
    position = None if at is None else at / h  # in steps from the start
    t_at, x_at, next_at = [], [], 0
    done, nonfinite, interrupted = 0, None, False

    def last_saved():
        return int(steps[-1][-1]) if len(steps[-1]) else int(np.concatenate(steps)[-1])

    def take_times(x_start, first, last, final):
        """The requested times in (first, last] steps (from 0 in the first chunk; all the rest
        in the final one: a time at the very end may round past it)."""
        nonlocal next_at
        if at is None or next_at >= len(at):
            return
        upto = len(at) if final else int(np.searchsorted(position, last, side="right"))
        if upto > next_at:
            t_at.append(at[next_at:upto])
            x_at.append(_states_at(step, x_start, h, at[next_at:upto], first))
            next_at = upto

    try:
        while done < n_steps:
            if stop is not None and stop():
                interrupted = True
                break
            if aligned:
                n = min(chunk, n_steps - done)
                traj = integrate(step, x, h, n, save_every=save_every)
                xs = rows(host(traj.x), slice(1, None))
                local = np.arange(1, len(traj.t), dtype=np.int64) * save_every
                local[-1] = n
                x_end = rows(traj.x, -1)
            else:
                next_save = (done // save_every + 1) * save_every
                n = min(chunk, next_save - done, n_steps - done)
                x_end = integrate(step, x, h, n).final
                is_save = done + n == next_save or done + n == n_steps
                xs = _one(host(x_end))
                local = np.array([n], dtype=np.int64)
                if not _finite_rows(xs).all():
                    is_save = True  # handled below
                if not is_save:
                    xs, local = rows(xs, slice(0, 0)), local[:0]
            if not _finite_rows(xs).all():
                bad, last = first_nonfinite(step, x, h, n)
                keep = local < bad
                steps.append(done + local[keep])
                saved.append(rows(xs, keep))
                if done + bad - 1 > last_saved():
                    steps.append(np.array([done + bad - 1]))
                    saved.append(_one(last))
                take_times(x, done, done + bad - 1, final=False)
                nonfinite = done + bad
                done += bad - 1
                break
            take_times(x, done, done + n, final=done + n >= n_steps)
            steps.append(done + local)
            saved.append(xs)
            x = x_end
            done += n
            if progress is not None:
                progress.update(done)
        if interrupted and done > last_saved():  # keep the last state reached
            steps.append(np.array([done]))
            saved.append(_one(host(x)))
    finally:
        if progress is not None:
            progress.close(done if not interrupted else None)
    found = None if at is None else (np.concatenate(t_at) if t_at else at[:0])
    states_at = None if at is None else (concatenate(x_at) if x_at else rows(saved[0], slice(0, 0)))
    return RunResult(np.concatenate(steps), concatenate(saved), done, nonfinite, interrupted,
                     time.perf_counter() - start, found, states_at)
