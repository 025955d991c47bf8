"""XLA's CPU tuning, as an explicit call: importing jaxsplit changes no global state.

XLA's CPU code generator asks LLVM for 256-bit vectors even where the CPU has 512-bit ones (a
hedge against the clock slow-down of wide instructions on older server chips); elementwise
loops over a batch run faster with the wider ones (``benchmarks/results/vector_width.md``).
Two ways to have them, both yours to choose:

* ``compiler_options()`` for one program: ``jax.jit(f, compiler_options=jaxsplit.compiler_options())``;
* ``tune_cpu()`` for the whole process, before JAX starts its backend: it adds the option to
  ``XLA_FLAGS`` (a value you set yourself stands). The command line calls it for its runs.

The stepping loop's other CPU tuning, one compiled kernel per loop, is per program and needs
no setting (``core._one_kernel``).
"""

import functools
import os
import sys

VECTOR_OPTION = "xla_cpu_prefer_vector_width"
VECTOR_BITS = 512


@functools.cache
def compiler_options() -> dict:
    """``{"xla_cpu_prefer_vector_width": 512}`` on the CPU backend, ``{}`` on others or where
    your ``XLA_FLAGS`` sets the width (yours stands): pass it to your own ``jax.jit``. On a CPU
    without 512-bit vectors LLVM uses the widest it has. Starts JAX's backend.

    >>> import jax, jaxsplit
    >>> jaxsplit.compiler_options() == ({"xla_cpu_prefer_vector_width": 512} if jax.default_backend() == "cpu" else {})
    True
    """
    import jax

    if f"--{VECTOR_OPTION}=" in os.environ.get("XLA_FLAGS", "") or jax.default_backend() != "cpu":
        return {}
    return {VECTOR_OPTION: VECTOR_BITS}


def with_wide_vectors(flags: str) -> str | None:
    """``flags`` (an ``XLA_FLAGS`` value) with the vector width added, or None where ``flags``
    already sets it (the user's choice stands)."""
    if f"--{VECTOR_OPTION}=" in flags:
        return None
    return " ".join(flags.split() + [f"--{VECTOR_OPTION}={VECTOR_BITS}"])


def _backend_started() -> bool:
    if "jax" not in sys.modules:  # without JAX imported no backend can have started
        return False
    try:
        from jax._src import xla_bridge
        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without this query: assume started, change nothing
        return True


def tune_cpu(environ=os.environ) -> str:
    """Ask XLA for 512-bit vectors in every program of this process (``XLA_FLAGS``), where that
    can still take effect: before JAX starts its backend. Returns what is in force:
    ``"on: …"``, ``"yours: …"`` (your ``XLA_FLAGS`` sets the width) or ``"off: …"`` (too late).
    Results are bit-identical in ``benchmarks/vector_width.py``; XLA does not promise it, so
    the command line records ``XLA_FLAGS`` with every run.

    >>> import jaxsplit
    >>> jaxsplit.tune_cpu({"XLA_FLAGS": "--xla_cpu_prefer_vector_width=256"})
    'yours: XLA_FLAGS sets --xla_cpu_prefer_vector_width=256'
    """
    flags = environ.get("XLA_FLAGS", "")
    updated = with_wide_vectors(flags)
    if updated is None:
        own = next(t for t in flags.split() if t.startswith(f"--{VECTOR_OPTION}="))
        return ("on: " if own == f"--{VECTOR_OPTION}={VECTOR_BITS}" else "yours: XLA_FLAGS sets ") + own
    if _backend_started():
        return "off: JAX's backend started before tune_cpu() (XLA's default vector width)"
    environ["XLA_FLAGS"] = updated
    return f"on: --{VECTOR_OPTION}={VECTOR_BITS}"
