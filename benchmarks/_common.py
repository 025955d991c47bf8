"""Helpers shared by the benchmark scripts (timing, machine info, matrix-free flows).

Nothing here is library code: ``ScalarRotation`` and ``Barrier`` are the benchmarks'
demonstrations of the speed-ups suggested in ``benchmarks/README.md``.
"""

import dataclasses
import os
import platform
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxsplit


def interleaved(cases: dict, repeats: int) -> dict:
    """Run every case once per round, ``repeats`` rounds; seconds per call, per case."""
    times = {name: [] for name in cases}
    for _ in range(repeats):
        for name, fn in cases.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times


def paired_ratio(times: dict, name: str, base: str) -> float:
    """Median over rounds of time[name] / time[base] (same round, so same load)."""
    return statistics.median(a / b for a, b in zip(times[name], times[base]))


def aot(fn, *args):
    """Compile ``jit(fn)`` for ``args`` ahead of time; (compiled, compile seconds)."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def ready(compiled, *args):
    return lambda: jax.block_until_ready(compiled(*args))


def machine_info(command: str) -> dict:
    import scipy

    return {
        "command": command,
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs (shared with other jobs)",
        "git": git_state(),
        "load_average_at_start": [round(v, 2) for v in os.getloadavg()],
        "versions": {"python": platform.python_version(), "jax": jax.__version__, "numpy": np.__version__,
                     "scipy": scipy.__version__, "jaxsplit": jaxsplit.__version__},
    }


def fmt(seconds: float) -> str:
    if seconds >= 1:
        return f"{seconds:.3g} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds * 1e6:.3g} µs"


def git_state() -> str:
    """HEAD commit, and whether the rotation code in the working tree differs from it."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "diff", "--name-only", "HEAD", "--", "jaxsplit"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (f" + uncommitted changes in {', '.join(dirty)}" if dirty else "")


class MatrixRotation(jaxsplit.AxisRotation):
    """The rotation as a 3x3 matrix product (``rotation_matrix(axis, angle) @ m``), as
    ``AxisRotation`` computes it at commit 7b2b6c7, whatever the working tree holds."""

    def __call__(self, m, t, body):
        angle = self.rate(body, m.dtype) * m[self.axis] * t
        return jaxsplit.rotation_matrix(self.axis, angle) @ m


class ScalarRotation(jaxsplit.AxisRotation):
    """jaxsplit's AxisRotation with the 3x3 matrix replaced by a two-component update."""

    def __call__(self, m, t, body):
        k = self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        theta = self.rate(body, m.dtype) * m[k] * t
        c, s = jnp.cos(theta), jnp.sin(theta)
        out = [None] * 3
        out[k], out[i], out[j] = m[k], c * m[i] + s * m[j], -s * m[i] + c * m[j]
        return jnp.stack(out)


class CorrectionRotation(jaxsplit.AxisRotation):
    """The rotation as a correction in its plane, m + e_i((c−1)m_i + s m_j) + e_j((c−1)m_j − s m_i):
    the form the working tree's ``_rotations.rotate`` had at 20:50 UTC on 2026-11-21 (a
    candidate under test, copied here so the benchmark does not move with the tree)."""

    def __call__(self, m, t, body):
        k = self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        theta = self.rate(body, m.dtype) * m[k] * t
        c, s = jnp.cos(theta), jnp.sin(theta)
        e_i, e_j = (jnp.asarray(np.eye(3)[q], dtype=m.dtype) for q in (i, j))
        return m + e_i * ((c - 1) * m[i] + s * m[j]) + e_j * ((c - 1) * m[j] - s * m[i])


@dataclasses.dataclass(frozen=True)
class Barrier:
    """A flow whose output is materialised (``lax.optimization_barrier``): stops XLA from
    fusing a whole composition into one elementwise kernel that recomputes every earlier
    sub-flow for each output component."""

    flow: object

    def __call__(self, m, t, params):
        return jax.lax.optimization_barrier(self.flow(m, t, params))


def step_variant(body, scheme: str, split: str, variant: str, shift_axis=2):
    """A jaxsplit step: ``library`` (``jaxsplit.splitting`` as the working tree has it),
    ``matrix`` (3x3-matrix flows), ``scalar`` (two-component flows, stacked),
    ``correction`` (see ``CorrectionRotation``), each optionally
    ``+barrier`` (every flow behind an optimization barrier); all but ``library`` go
    through the library's generic composer ``jaxsplit.compose``."""
    if variant == "library":
        return jaxsplit.splitting(body, scheme, split, shift_axis=shift_axis)
    flows = jaxsplit.rigid_body_flows(body, split, shift_axis)
    if variant.startswith("scalar"):
        flows = tuple(ScalarRotation(f.axis, f.shift) for f in flows)
    elif variant.startswith("correction"):
        flows = tuple(CorrectionRotation(f.axis, f.shift) for f in flows)
    elif variant.startswith("matrix"):
        flows = tuple(MatrixRotation(f.axis, f.shift) for f in flows)
    if variant.endswith("barrier"):
        flows = tuple(Barrier(f) for f in flows)
    return jaxsplit.compose(flows, scheme, body)
