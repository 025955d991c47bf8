"""XLA's CPU runtime and small loops: one setting, applied when jaxsplit is imported.

XLA runs a ``while`` loop on the CPU as one dispatched kernel per fused operation per
iteration, unless one iteration touches fewer bytes than its option
``xla_cpu_small_while_loop_byte_threshold`` (1 KiB by default): then the whole loop is one
compiled kernel. A composition step on one body, a heavy top or a few bodies is dozens of
tiny fused operations, so under the default their dispatch, not the arithmetic, sets the
time (``benchmarks/results/small_loops.md``: a heavy top's reversible gradient over 10⁵
steps 2.2× faster, one body with Kahan–Li 8 1.6× faster; 3.1× and 1.2× in an earlier run). On hundreds of bodies each fused
operation has enough work to hide its dispatch: one kernel ran no faster and compiled up to
a third longer, and on 10⁵ bodies it loses XLA's multi-threading. Hence the bound below:
64 KiB per iteration, one body or a top with any scheme, up to ~50 bodies with an
eighth-order one.

``import jaxsplit`` raises the option to ``SMALL_LOOP_BYTES`` through ``XLA_FLAGS`` (inside
``--xla_backend_extra_options``, which XLA reads once, when JAX starts its backend) unless
you set it yourself, which is also how to opt out (``…=1024`` restores XLA's default), or
JAX's backend has already started (then nothing changes). ``small_loop_setting()`` says
which happened. Results were bit-identical in every run of that benchmark; XLA does not
promise it (a 256-body run of the general cos/sin kernel under ``jit`` differed at 4e-12
after 2,000 steps: another, equally rounded sin/cos), so bit-reproducibility is per setting,
and the command line records ``XLA_FLAGS`` with every run.
"""

import functools
import os
import sys

OPTION = "xla_cpu_small_while_loop_byte_threshold"
SMALL_LOOP_BYTES = 64 * 2**10
_EXTRA = "--xla_backend_extra_options="
_ON = f"on: loops touching < {SMALL_LOOP_BYTES // 2**10} KiB per iteration compile to one kernel"


def _backend_options(flags: str):
    """(key, value) of every entry of every ``--xla_backend_extra_options`` in ``flags``, in order."""
    for token in flags.split():
        if token.startswith(_EXTRA):
            for entry in filter(None, token[len(_EXTRA):].split(",")):
                key, _, value = entry.partition("=")
                yield key, value


def with_small_loops(flags: str, threshold: int = SMALL_LOOP_BYTES) -> str | None:
    """``flags`` (an ``XLA_FLAGS`` value) with ``OPTION=threshold`` added to its backend
    options, or None where ``flags`` already sets ``OPTION`` (the user's choice stands)."""
    if any(key == OPTION for key, _ in _backend_options(flags)):
        return None
    tokens = flags.split()
    extras = [k for k, token in enumerate(tokens) if token.startswith(_EXTRA)]
    setting = f"{OPTION}={threshold}"
    if extras:  # XLA keeps the last occurrence of a flag: extend that one
        last = extras[-1]
        tokens[last] = tokens[last] + ("," if tokens[last] != _EXTRA else "") + setting
    else:
        tokens.append(_EXTRA + setting)
    return " ".join(tokens)


def threshold_in(flags: str) -> int | None:
    """The threshold an ``XLA_FLAGS`` value sets (its last setting; None if none or not an integer)."""
    values = [value for key, value in _backend_options(flags) if key == OPTION]
    return int(values[-1]) if values and values[-1].strip().isdigit() else None


def _backend_started() -> bool:
    if "jax" not in sys.modules:  # without JAX imported no backend can have started (JAX is not imported here)
        return False
    try:
        from jax._src import xla_bridge
        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without this query: assume started, change nothing
        return True


def apply_small_loops(environ=os.environ) -> str:
    """Set the option in ``environ['XLA_FLAGS']`` where it can still take effect; returns
    ``small_loop_setting()``'s answer."""
    flags = environ.get("XLA_FLAGS", "")
    updated = with_small_loops(flags)
    if updated is None:
        own = threshold_in(flags)
        return _ON if own == SMALL_LOOP_BYTES else f"yours: XLA_FLAGS sets {OPTION}={own}"  # ours: inherited
    if _backend_started():
        return "off: JAX's backend started before jaxsplit was imported (XLA's default, 1 KiB)"
    environ["XLA_FLAGS"] = updated
    return _ON


@functools.cache  # applied once, at import
def small_loop_setting() -> str:
    """Whether XLA compiles jaxsplit's small loops as one kernel: ``"on: …"`` (set at import,
    or already in ``XLA_FLAGS``), ``"yours: …"`` (your ``XLA_FLAGS`` set another threshold) or
    ``"off: …"`` (JAX's backend had started before ``import jaxsplit``).

    >>> import jaxsplit
    >>> jaxsplit.small_loop_setting()      # in a fresh process, before any JAX computation
    'on: loops touching < 64 KiB per iteration compile to one kernel'
    """
    return apply_small_loops()
