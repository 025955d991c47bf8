"""XLA's CPU settings: small loops as one kernel (set when jaxsplit is imported) and wide
vectors for jaxsplit's own programs (``compiler_options``, ``jit``; end of this module).

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
eighth-order one. Above it jaxsplit's own stepping loop is still one kernel, per program
(``core._one_kernel``: up to 64 KiB of state, where a few hundred bodies gain 1.2×), which
leaves other programs (diffrax's) as XLA compiles them.

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


# ------------------------------------------------------------------ vector width, per program
# XLA's CPU code generator asks LLVM for 256-bit vectors even where the CPU has 512-bit ones (a
# hedge against the clock slow-down of wide instructions on older server chips). A batch laid out
# components-first is long elementwise loops, which 512-bit vectors run faster
# (``benchmarks/results/vector_width.md``): Kahan–Li 8 / McLachlan SS15 on 16 to 4096 bodies 1.4–1.5×,
# one body, a heavy top and its gradient, and 10⁵ bodies unchanged, results bit-identical. Unlike the
# small-loop option this one is a plain compiler option, so it is set per program, on jaxsplit's own.
VECTOR_OPTION = "xla_cpu_prefer_vector_width"
VECTOR_BITS = 512


@functools.cache
def compiler_options() -> dict:
    """The XLA compiler options of jaxsplit's own compiled runs (``integrate``, sweeps, order
    fits): ``{"xla_cpu_prefer_vector_width": 512}`` on the CPU backend, ``{}`` on others or where
    your ``XLA_FLAGS`` sets the width (yours stands). On a CPU without 512-bit vectors LLVM uses
    the widest it has. Pass it to your own ``jax.jit`` around jaxsplit steps for the same code:
    ``jax.jit(f, compiler_options=jaxsplit.compiler_options())``. Starts JAX's backend.

    >>> import jax, jaxsplit
    >>> jaxsplit.compiler_options() == ({"xla_cpu_prefer_vector_width": 512} if jax.default_backend() == "cpu" else {})
    True
    """
    import jax

    if f"--{VECTOR_OPTION}=" in os.environ.get("XLA_FLAGS", "") or jax.default_backend() != "cpu":
        return {}
    return {VECTOR_OPTION: VECTOR_BITS}


def _top_level() -> bool:
    """No trace is active (JAX refuses compiler options on a ``jit`` nested in any trace)."""
    try:
        from jax._src import core
        return bool(core.trace_state_clean())
    except (ImportError, AttributeError):  # a JAX without this query: never pass the options
        return False


def jit(fun=None, **jit_kwargs):
    """``jax.jit(fun, **jit_kwargs)`` with ``compiler_options()`` where it is called at top level;
    inside ``jit``, ``grad`` or ``vmap`` the plain ``jax.jit`` (JAX takes compiler options on
    top-level programs only; there the outer program's options apply). Built at the first call:
    the backend is known only then, and importing jaxsplit must not start it."""
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    built = {}

    @functools.wraps(fun)
    def call(*args, **kwargs):
        top = _top_level()
        if top not in built:
            import jax

            built[top] = jax.jit(fun, compiler_options=(compiler_options() or None) if top else None, **jit_kwargs)
        return built[top](*args, **kwargs)

    return call
