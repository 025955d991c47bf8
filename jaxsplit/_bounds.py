"""Bounds on every size a user controls, checked before any work starts: the one bound-checker
of the library and of the command line (which passes its option names as the labels).

Counts (steps, saved states, cases, samples, iterations) pass through ``count``, any size
through ``at_most``, memory estimates through ``memory``, so a refusal always reads the same
way: what, its value, the bound, why the bound exists and how to fit under it. The bounds come
from what breaks beyond them, not from taste: representability (step indices exact in
float64), memory (an estimate against the memory available where the arrays will live) and
compile time (measured per stage). Imports no JAX (the command line checks before JAX loads);
the device is passed in where it matters.
"""

import math
import os
import re

from ._errors import InputError

# Step indices and the times k*h are exact in float64 up to 2^53.
MAX_COUNT = 2**53
# The unrolled step compiles in ~0.1 s and ~1.6 MB per stage (triple-jump-14, 729 stages:
# 77 s and 1.2 GB on this machine's CPU); beyond ~1000 stages compilation takes minutes.
MAX_STAGES = 1000
WHY_STAGES = "compile time and memory grow with the stages"


def _shown(value) -> str:
    return f"{value:,}" if isinstance(value, int) else f"{value:.3g}"


def at_most(value, limit, what: str, why: str, hint: str = ""):
    """``value`` when it is <= ``limit``; else an ``InputError`` naming all of it."""
    if value > limit:
        raise InputError(f"{what} is {_shown(value)}, more than the {limit:,} allowed ({why})"
                         + (f"; {hint}" if hint else ""))
    return value


def _limit(value: int) -> str:
    return "2^53" if value == MAX_COUNT else f"{value:,}"


def count(value, name: str, minimum: int = 1, maximum: int = MAX_COUNT, why: str = "") -> int:
    """``value`` as a Python int in [minimum, maximum]: an integer (not a bool, not a float).
    ``why`` says where ``maximum`` comes from when it is not the float64 bound 2^53."""
    import numpy as np

    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer))
            or not minimum <= value <= maximum):
        reason = f" ({why})" if why and isinstance(value, (int, np.integer)) and value > maximum else ""
        raise InputError(f"{name} must be an integer in [{minimum}, {_limit(maximum)}], got {value!r}{reason}")
    return int(value)


# ------------------------------------------------------------------ memory
def available_memory(device=None) -> int:
    """Bytes free now where arrays will live: an accelerator's free memory when ``device`` is one
    that reports it, else the host's (MemAvailable on Linux; total memory otherwise)."""
    if device is not None and getattr(device, "platform", "cpu") != "cpu":
        try:
            stats = device.memory_stats() or {}
            if "bytes_limit" in stats:
                return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
        except Exception:  # noqa: BLE001, S110 - a backend without statistics: the host's memory below
            pass
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


def memory_limit(max_memory: int | None, device=None) -> int:
    """``max_memory`` when given (any size >= 1 byte counts), else half the available memory
    (the other half for the arrays the work itself makes: copies, temporaries, results)."""
    return available_memory(device) // 2 if max_memory is None else max_memory


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def array_bytes(tree) -> int:
    """Bytes of the array leaves of ``tree`` (anything with a shape and a dtype, traced too)."""
    import jax
    import numpy as np

    return sum(int(np.prod(np.shape(leaf))) * np.dtype(leaf.dtype).itemsize
               for leaf in jax.tree_util.tree_leaves(tree) if hasattr(leaf, "dtype"))


def memory(need: int, limit: int, what: str, hint: str, limit_name: str = "half the memory available now") -> int:
    """Refuse when ``need`` bytes exceed ``limit`` (named by ``limit_name``)."""
    if need > limit:
        raise InputError(f"{what} would need about {format_bytes(need)} of memory but the limit is "
                         f"{format_bytes(limit)} ({limit_name}); {hint}")
    return need


def fits(need: int, what: str, hint: str, device=None) -> int:
    """The library's memory bound: ``need`` bytes (the estimate counts the work's own copies and
    temporaries) must fit in the memory available now where the arrays will live."""
    return memory(need, available_memory(device), what, hint, "the memory available now")


def saved_states(n_steps: int, save_every: int, bytes_per_saved: int, limit: int, extra: int = 0, *,
                 every: str = "save_every", at: str = "ts", limit_name: str = "half the memory available now") -> int:
    """Bytes of a run saving every ``save_every``-th state (and the first and last ones) and
    ``extra`` states at requested times (option ``at``); the hint names option ``every``."""
    n_saved = n_steps // save_every + 2 + extra
    if extra and extra * bytes_per_saved > limit // 2:
        return memory(n_saved * bytes_per_saved, limit, f"the trajectory ({n_saved:,} saved states, {extra:,} of them "
                      f"at {at} times)", f"give fewer {at} times", limit_name)
    suggest = max(save_every + 1, math.ceil(n_steps * bytes_per_saved / (0.5 * limit)))
    flag = f"{every} {suggest}" if every.startswith("--") else f"{every}={suggest}"
    return memory(n_saved * bytes_per_saved, limit, f"the trajectory ({n_saved:,} saved states)",
                  f"save fewer states, e.g. {flag}", limit_name)


# ------------------------------------------------------------------ schemes
_TRIPLE_JUMP = re.compile(r"triple-jump-(\d+)")
LARGEST_TRIPLE_JUMP = 2 + 2 * int(math.log(MAX_STAGES, 3))


def triple_jump_order(order, what: str) -> int:
    """A triple jump's order, refused before its 3^((order-2)/2) stages are built when they
    would exceed ``MAX_STAGES`` (order 10^6 would exhaust any memory)."""
    power = (order - 2) // 2
    if power > math.log(MAX_STAGES, 3):
        stages = f"3^{power:,}" if power < 10**6 else "3^((N-2)/2)"
        raise InputError(f"{what} has {stages} stages, more than the {MAX_STAGES:,} allowed ({WHY_STAGES}); "
                         f"triple-jump-{LARGEST_TRIPLE_JUMP} is the largest")
    return order


def triple_jump_name(name: str, what: str) -> str:
    """``name``, refused as ``triple_jump_order`` does when it names a triple jump of too many
    stages (a huge digit string is refused without converting it: Python limits int())."""
    match = _TRIPLE_JUMP.fullmatch(name) if isinstance(name, str) else None
    if match:
        digits = match.group(1)
        triple_jump_order(int(digits) if len(digits) <= 12 else 10**13, what)
    return name


def stages(scheme, what: str):
    """``scheme`` when its stages are at most ``MAX_STAGES``."""
    at_most(scheme.stages, MAX_STAGES, f"{what}: the number of stages", WHY_STAGES)
    return scheme
