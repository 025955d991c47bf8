"""Bounds on every size a user controls, checked before any work starts: the library's
bound-checker (``jaxsplit._bounds``) with the command line's option names.

Step counts, saved states, cases, scheme stages, ladder sizes and memory all pass through
``at_most`` (or a helper built on it), so a refusal always reads the same way: the option,
its value, the bound, why the bound exists and how to fit under it (exit status 2, nothing
run, nothing written). The bounds come from what breaks beyond them, not from taste:
representability (float64 step indices, int32 loop counters), memory (measured bytes per
saved state or case against ``--max-memory``) and compile time (measured per stage).
"""

import math

from .. import _bounds as _lib
from .._bounds import MAX_STAGES, at_most, available_memory, format_bytes, memory_limit  # noqa: F401 (shared)
from .._errors import InputError

MAX_STEPS = _lib.MAX_COUNT  # step indices and the times k*h are exact in float64 up to 2^53
# numpy's seeds are non-negative and fit 128 bits; the CLI keeps them to 64.
MAX_SEED = 2**64 - 1


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


# ------------------------------------------------------------------ memory and schemes: the library's checks
LIMIT = "--max-memory"


def memory(need: int, limit: int, what: str, hint: str) -> int:
    """Refuse when ``need`` bytes exceed ``limit`` (``--max-memory``)."""
    return _lib.memory(need, limit, what, hint, LIMIT)


def saved_states(n_steps: int, save_every: int, bytes_per_saved: int, limit: int, extra: int = 0) -> int:
    """The library's estimate of a saved trajectory, its hints naming the CLI's options."""
    return _lib.saved_states(n_steps, save_every, bytes_per_saved, limit, extra, every="--save-every",
                             at="--save-at", limit_name=LIMIT)


def scheme(name: str, option: str = "--scheme"):
    """The registered scheme ``name`` with at most ``MAX_STAGES`` stages, refused before it is
    built (the library's ``triple_jump`` refuses the same orders, naming the function)."""
    from ..core._schemes import schemes

    _lib.triple_jump_name(name, f"{option} {name}")
    return _lib.stages(schemes[name], f"{option} {name}")
