"""Long integrations in chunks of equal size: one compilation, a finite-state check and a
chance to stop after every chunk, and the first non-finite step found exactly.

``run_chunked`` saves like ``integrate(..., save_every=k)`` (x0, every k-th state, the
last one). It stops at the first non-finite state (keeping the last finite one) or when
``stop()`` turns true between chunks (the signal policy's ``requested``); either way the
states computed so far are returned, never lost.
"""

import time
from typing import NamedTuple

import numpy as np

TARGET_FLOWS_PER_CHUNK = 1_000_000  # ~0.05-0.4 s of work per chunk on a CPU core


class RunResult(NamedTuple):
    """Saved states of a chunked run: ``x[i]`` after ``steps[i]`` steps."""

    steps: np.ndarray
    x: np.ndarray
    completed: int  # steps completed with a finite state
    nonfinite_step: int | None  # first step whose state is not finite
    interrupted: bool
    seconds: float


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


def _finite_rows(x: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(x.reshape(len(x), -1)), axis=1) if len(x) else np.ones(0, bool)


def first_nonfinite(step, x, h, n: int) -> tuple[int, np.ndarray]:
    """Within ``n`` steps from the finite state ``x``: (first step k >= 1 whose state is not
    finite, the state after k - 1 steps). Narrows down by blocks, 1024 saves at a time."""
    from ..core._integrate import integrate

    offset = 0
    while True:
        block = max(1, -(-n // 1024))
        traj = integrate(step, x, h, n, save_every=block)
        xs = np.asarray(traj.x)
        counts = np.minimum(np.arange(len(xs)) * block, n)
        bad = np.flatnonzero(~_finite_rows(xs))
        if len(bad) == 0:  # round-off differences between runs: treat the last step as bad
            return offset + n, xs[-1]
        i = int(bad[0])
        if block == 1:
            return offset + int(counts[i]), xs[i - 1]
        offset += int(counts[i - 1])
        n = int(counts[i] - counts[i - 1])
        x = traj.x[i - 1]


def run_chunked(step, x0, h, n_steps: int, save_every: int, *, flows_per_step: int = 1,
                chunk: int | None = None, progress=None, stop=None) -> RunResult:
    """Integrate in chunks of equal size (the compiled scan is reused), checking after each
    chunk that the state is finite. Saves ``x0``, every ``save_every``-th state and the last
    one, like ``integrate(..., save_every=...)``. A non-finite state stops the run at the
    first bad step; ``stop()`` turning true stops it after the current chunk; either way
    the states computed so far are returned (with the last good state)."""
    import jax.numpy as jnp

    from ..core._integrate import integrate

    chunk = chunk or chunk_size(n_steps, save_every, flows_per_step)
    aligned = chunk % save_every == 0  # else save_every > chunk: saves fall on chunk ends
    start = time.perf_counter()
    x = jnp.asarray(x0)
    steps, saved = [np.zeros(1, dtype=np.int64)], [np.asarray(x)[None]]
    done, nonfinite, interrupted = 0, None, False

    def last_saved():
        return int(steps[-1][-1]) if len(steps[-1]) else int(np.concatenate(steps)[-1])

    try:
        while done < n_steps:
            if stop is not None and stop():
                interrupted = True
                break
            if aligned:
                n = min(chunk, n_steps - done)
                traj = integrate(step, x, h, n, save_every=save_every)
                xs = np.asarray(traj.x)[1:]
                local = np.arange(1, len(xs) + 1, dtype=np.int64) * save_every
                local[-1] = n
                x_end = traj.x[-1]
            else:
                next_save = (done // save_every + 1) * save_every
                n = min(chunk, next_save - done, n_steps - done)
                x_end = integrate(step, x, h, n).final
                is_save = done + n == next_save or done + n == n_steps
                xs = np.asarray(x_end)[None]
                local = np.array([n], dtype=np.int64)
                if not np.all(np.isfinite(xs)):
                    is_save = True  # handled below
                if not is_save:
                    xs, local = xs[:0], local[:0]
            if not _finite_rows(xs).all():
                bad, last = first_nonfinite(step, x, h, n)
                keep = local < bad
                steps.append(done + local[keep])
                saved.append(xs[keep])
                if done + bad - 1 > last_saved():
                    steps.append(np.array([done + bad - 1]))
                    saved.append(np.asarray(last)[None])
                nonfinite = done + bad
                done += bad - 1
                break
            steps.append(done + local)
            saved.append(xs)
            x = x_end
            done += n
            if progress is not None:
                progress.update(done)
        if interrupted and done > last_saved():  # keep the last state reached
            steps.append(np.array([done]))
            saved.append(np.asarray(x)[None])
    finally:
        if progress is not None:
            progress.close(done if not interrupted else None)
    return RunResult(np.concatenate(steps), np.concatenate(saved), done, nonfinite, interrupted,
                     time.perf_counter() - start)
