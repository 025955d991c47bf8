"""Helpers shared by the benchmark scripts: interleaved timing, paired ratios, the machine
record, and writing one results table per script."""

import itertools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np

import jaxsplit

RESULTS = Path(__file__).resolve().parent / "results"

# How tables and plots name the registry's schemes: author, order (the registry's names are kebab-case keys).
SCHEME_LABELS = {"strang": "Strang (order 2)", "blanes-moan-s6-prk": "Blanes–Moan S6 partitioned (order 4)",
                 "kahan-li-6": "Kahan–Li (order 6)", "kahan-li-8": "Kahan–Li (order 8)",
                 "kahan-li-10": "Kahan–Li (order 10)", "mclachlan-ss15": "McLachlan SS15 (order 8)",
                 "mclachlan-ss17": "McLachlan SS17 (order 8)", "sofroniou-spaletta-10": "Sofroniou–Spaletta (order 10)"}


def scheme_label(name: str) -> str:
    return SCHEME_LABELS.get(name, name)


def log(msg: str):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def interleaved(cases: dict, repeats: int, clock=time.perf_counter) -> dict:
    """Run every case once per round, ``repeats`` rounds (load from other jobs hits all
    cases alike); seconds per call, per case, by ``clock`` (``time.process_time``: the CPU
    time of this process, which other jobs' load does not inflate)."""
    times = {name: [] for name in cases}
    for _ in range(repeats):
        for name, fn in cases.items():
            t0 = clock()
            fn()
            times[name].append(clock() - t0)
    return times


def paired_ratio(times: dict, name: str, base: str) -> float:
    """Median over rounds of time[name] / time[base] (same round, so same load)."""
    return statistics.median(a / b for a, b in zip(times[name], times[base]))


def ready(fn, *args):
    """A call of the compiled ``fn(*args)`` that waits for the result."""
    return lambda: jax.block_until_ready(fn(*args))


def time_to_reach(points, target: float):
    """The least time at which (error, time) points reach error ``target``: walking the points in
    order of time, the first step from above ``target`` to at or below it, interpolated log-log
    (None if never crossed). Near the round-off floor errors stop falling with cost; sorting by
    error instead paired points that are not neighbours in cost (Sofroniou–Spaletta 10 at 1e-8:
    its 1250- and 2500-step runs, 57 ms, skipping the 1800-step run that reached 7.5e-10 in 63 ms)."""
    pts = sorted((t, e) for e, t in points if e > 0)
    for (t_lo, e_lo), (t_hi, e_hi) in itertools.pairwise(pts):
        if e_hi <= target < e_lo:
            w = (math.log(target) - math.log(e_lo)) / (math.log(e_hi) - math.log(e_lo))
            return math.exp(math.log(t_lo) + w * (math.log(t_hi) - math.log(t_lo)))
    return None


def fmt(seconds: float) -> str:
    if seconds >= 1:
        return f"{seconds:.3g} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds * 1e6:.3g} µs"


def device_name() -> str:
    """``cpu``, or the accelerator's platform and model (``gpu (NVIDIA H100 80GB HBM3)``)."""
    device = jax.devices()[0]
    return device.platform if device.platform == "cpu" else f"{device.platform} ({device.device_kind})"


def cpu_name() -> str:
    """The processor as Linux names it, with its family and model and whether it has AVX-512
    (``AMD EPYC (family 25, model 17), AVX-512``): ratios against peers moved by 1.5-1.9× between
    hosts (``README.md``, work-precision runs), so every record says which one it ran on."""
    try:
        fields = dict(line.split(":", 1) for line in Path("/proc/cpuinfo").read_text().splitlines()[:30]
                      if ":" in line)
    except OSError:
        return platform.processor() or "unknown processor"
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    avx512 = ", AVX-512" if "avx512f" in fields.get("flags", "").split() else ""
    return f"{fields.get('model name', '?')} (family {fields.get('cpu family', '?')}, model {fields.get('model', '?')}){avx512}"


def machine_info(command: str) -> dict:
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "jaxsplit"], cwd=root, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        head, dirty = "unknown", ""
    return {
        "command": command,
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs ({cpu_name()}; shared with other jobs), {device_name()}",
        "git": head + (" + uncommitted library changes" if dirty else ""),
        "load_average_at_start": [round(v, 2) for v in os.getloadavg()],
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "versions": {"python": platform.python_version(), "jax": jax.__version__, "numpy": np.__version__,
                     "jaxsplit": jaxsplit.__version__},
    }


def header(out: dict, title: str) -> list[str]:
    return [f"## {title}", "", (f"`{out['command']}` — {out['date_utc']}; {out['machine']}; load average at start "
            f"{', '.join(f'{v:.1f}' for v in out['load_average_at_start'])}; JAX {out['versions']['jax']}; "
            f"jaxsplit at {out['git']}; XLA_FLAGS `{out.get('xla_flags') or ''}`."), ""]


def finish(stem: str, out: dict, lines: list[str], start: float, quick: bool = False):
    """Record the wall time since ``start`` (``time.perf_counter()``) and ``write`` the results."""
    out["wall_s"] = time.perf_counter() - start
    write(stem, quick, out, lines + ["", f"Total wall time {out['wall_s']:.0f} s."])


def result_path(stem: str, suffix: str, quick: bool = False) -> Path:
    """``results/<stem>[-quick][-<backend>].<suffix>``: a quick run or one on an accelerator
    (``-gpu``) never overwrites the full CPU record."""
    RESULTS.mkdir(exist_ok=True)
    backend = jax.default_backend()
    return RESULTS / f"{stem}{'-quick' if quick else ''}{'' if backend == 'cpu' else '-' + backend}.{suffix}"


def write(stem: str, quick: bool, out: dict, lines: list[str]):
    """``result_path(stem, 'json' and 'md', quick)``; the table is printed too."""
    result_path(stem, "json", quick).write_text(json.dumps(out, indent=1, default=float))
    result_path(stem, "md", quick).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
