"""Bounds on every size a user controls, checked before any work starts.

Step counts, saved states, cases, scheme stages, ladder sizes and memory all pass through
``at_most`` (or a helper built on it), so a refusal always reads the same way: the option,
its value, the bound, why the bound exists and how to fit under it (exit status 2, nothing
run, nothing written). The bounds come from what breaks beyond them, not from taste:
representability (float64 step indices, int32 loop counters), memory (measured bytes per
saved state or case against ``--max-memory``) and compile time (measured per stage).
"""

import math
import os
import re

from ..core._errors import InputError

# Step indices and the times k*h are exact in float64 up to 2^53.
MAX_STEPS = 2**53
# The unrolled step compiles in ~0.1 s and ~1.6 MB per stage (triple-jump-14, 729 stages:
# 77 s and 1.2 GB on this machine's CPU); beyond ~1000 stages compilation takes minutes.
MAX_STAGES = 1000
# numpy's seeds are non-negative and fit 128 bits; the CLI keeps them to 64.
MAX_SEED = 2**64 - 1


def at_most(value, limit, what: str, why: str, hint: str = "") -> int:
    """``value`` when it is <= ``limit``; else an ``InputError`` naming all of it."""
    if value > limit:
        shown = f"{value:,}" if isinstance(value, int) else f"{value:.3g}"
        raise InputError(f"{what} is {shown}, more than the {limit:,} allowed ({why})" + (f"; {hint}" if hint else ""))
    return value


def step_count(t_end: float, dt: float, *, limit: int = MAX_STEPS, why: str = "step indices exact in float64",
               options=("--t-end", "--dt"), notes=None, at_least_one: bool = True) -> int:
    """round(t_end / |dt|) without overflow, at most ``limit`` (and at least 1 unless the
    caller rounds a short run up to one step itself)."""
    t_opt, dt_opt = options
    steps = t_end / abs(dt)  # inf for 1e300 / 1e-300: refused below, never rounded
    if not math.isfinite(steps) or steps >= limit + 0.5:
        raise InputError(f"{t_opt} {t_end:g} / {dt_opt} {abs(dt):g} is {steps:.3g} steps, more than the {limit:,} "
                         f"allowed ({why}); use a larger {dt_opt.split()[0]} or a shorter {t_opt}")
    n = round(steps)
    if n < 1 and at_least_one:
        raise InputError(f"{t_opt} {t_end:g} is shorter than one step of {dt_opt} {dt:g}")
    if notes is not None and abs(n * abs(dt) - t_end) > 1e-9 * t_end:
        notes.append(f"--t-end {t_end:g} is not a whole number of steps of --dt {dt:g}; integrating {n:,} steps "
                     f"to t = {n * dt:g}")
    return n


# ------------------------------------------------------------------ memory
def available_memory() -> int:
    """Bytes of memory available now (MemAvailable on Linux; total memory otherwise)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 * 1024**3


def memory_limit(max_memory: int | None) -> int:
    """``--max-memory`` when given (any size >= 1 byte counts), else half the available memory."""
    return available_memory() // 2 if max_memory is None else max_memory


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def memory(need: int, limit: int, what: str, hint: str) -> int:
    """Refuse when ``need`` bytes exceed ``limit`` (``--max-memory``)."""
    if need > limit:
        raise InputError(f"{what} would need about {format_bytes(need)} of memory but the limit is "
                         f"{format_bytes(limit)} (--max-memory); {hint}")
    return need


def saved_states(n_steps: int, save_every: int, bytes_per_saved: int, limit: int, extra: int = 0) -> int:
    """Bytes of a run saving every ``save_every``-th state (and the first and last ones) and
    ``extra`` states at requested times (``--save-at``)."""
    n_saved = n_steps // save_every + 2 + extra
    if extra and extra * bytes_per_saved > limit // 2:
        return memory(n_saved * bytes_per_saved, limit, f"the trajectory ({n_saved:,} saved states, {extra:,} of them "
                      "at --save-at times)", "give fewer --save-at times")
    suggest = max(save_every + 1, math.ceil(n_steps * bytes_per_saved / (0.5 * limit)))
    return memory(n_saved * bytes_per_saved, limit, f"the trajectory ({n_saved:,} saved states)",
                  f"save fewer states, e.g. --save-every {suggest}")


# ------------------------------------------------------------------ schemes
_TRIPLE_JUMP = re.compile(r"triple-jump-(\d+)")


def scheme(name: str, option: str = "--scheme"):
    """The registered scheme ``name`` with at most ``MAX_STAGES`` stages, refused before it is
    built: a triple jump of order N has 3^((N-2)/2) stages and building one of order 10^6
    would exhaust memory."""
    from ..core._schemes import schemes

    match = _TRIPLE_JUMP.fullmatch(name)
    if match and name not in set(schemes):
        digits = match.group(1)  # int() of a huge digit string is itself refused by Python
        power = (int(digits) - 2) // 2 if len(digits) <= 6 else None
        if power is None or power > math.log(MAX_STAGES, 3):
            largest = 2 + 2 * int(math.log(MAX_STAGES, 3))
            stages = f"3^{power:,}" if power is not None else "3^((N-2)/2)"
            raise InputError(f"{option} {name} has {stages} stages, more than the {MAX_STAGES:,} allowed (compile "
                             f"time and memory grow with the stages); triple-jump-{largest} is the largest")
    s = schemes[name]
    at_most(s.stages, MAX_STAGES, f"{option} {name}: the number of stages",
            "compile time and memory grow with the stages")
    return s
