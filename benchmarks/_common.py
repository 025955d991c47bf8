"""Helpers shared by the benchmark scripts (timing, machine info, matrix-free flows).

Nothing here is library code: ``ScalarRotation`` and ``Barrier`` are the benchmarks'
demonstrations of the speed-ups suggested in ``benchmarks/README.md``.
"""

import os
import platform
import statistics
import time

import equinox as eqx
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


class _RotationVariant(jaxsplit.AbstractFlow):
    """A rotation about body ``axis`` by θ = rate·m_k·t in a pinned arithmetic form (so the
    benchmark does not move with the library)."""

    axis: int = eqx.field(static=True)
    rate: jax.Array

    def angle(self, m, t):
        return self.rate.astype(m.dtype) * m[self.axis] * t


class MatrixRotation(_RotationVariant):
    """The rotation as a 3x3 matrix product (``rotation_matrix(axis, angle) @ m``), as
    ``AxisRotation`` computed it at commit 7b2b6c7."""

    def __call__(self, m, t):
        return jaxsplit.rotation_matrix(self.axis, self.angle(m, t)) @ m


class ScalarRotation(_RotationVariant):
    """The two-component update, stacked."""

    def __call__(self, m, t):
        k = self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        theta = self.angle(m, t)
        c, s = jnp.cos(theta), jnp.sin(theta)
        out = [None] * 3
        out[k], out[i], out[j] = m[k], c * m[i] + s * m[j], -s * m[i] + c * m[j]
        return jnp.stack(out)


class CorrectionRotation(_RotationVariant):
    """The rotation as a correction in its plane, m + e_i((c−1)m_i + s m_j) + e_j((c−1)m_j − s m_i)
    (a candidate studied on 2026-11-21)."""

    def __call__(self, m, t):
        k = self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        theta = self.angle(m, t)
        c, s = jnp.cos(theta), jnp.sin(theta)
        e_i, e_j = (jnp.asarray(np.eye(3)[q], dtype=m.dtype) for q in (i, j))
        return m + e_i * ((c - 1) * m[i] + s * m[j]) + e_j * ((c - 1) * m[j] - s * m[i])


_VARIANTS = {"matrix": MatrixRotation, "scalar": ScalarRotation, "correction": CorrectionRotation}


def step_variant(body, scheme: str, split: str, variant: str, shift=1):
    """A jaxsplit step: ``library`` (``jaxsplit.splitting`` as the working tree has it) or
    the library's generic composer over flows of a pinned rotation form (``matrix``,
    ``scalar``, ``correction``; the composer puts an optimization barrier on every
    sub-flow, so ``+barrier`` names the same step)."""
    options = {"shift": shift} if split == "casimir" else {}
    if variant == "library":
        return jaxsplit.splitting(body, scheme, split, **options)
    flows = body.split(split, **options)
    cls = _VARIANTS[variant.removesuffix("+barrier")]
    return jaxsplit.compose(tuple(cls(f.axis, f.rate) for f in flows), scheme)
