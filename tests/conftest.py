"""Tests run in float64: structure preservation is judged at round-off."""

import importlib.metadata
import importlib.util
import os
import pathlib

# The suite compiles hundreds of programs and runs most of them briefly, so XLA's optimisation
# costs more than it saves: JAX's own switch for that (jax_disable_most_optimizations: backend
# optimisation level 0, no expensive LLVM passes) took the suite from 1578 to 1153 s of CPU
# (2026-11-27). Unoptimised code forms no fused multiply-adds; every tolerance here holds without
# them (the kernel's argument reduction was made exact without them for this), and
# tests/test_optimized.py runs the round-off-critical checks again as users compile them. The
# switch reaches the CLI's subprocesses and notebook kernels through the environment.
os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")

# Tests build their steps anew (new closures, new modules), so JAX traces them again and XLA
# compiled the same program again and again: in every worker, every CLI subprocess and notebook
# kernel. JAX's persistent cache is keyed by the program itself, so each distinct program is
# compiled once per run (and run, not timed: no test's assertion depends on it). One folder per
# run, shared with the workers and subprocesses through the environment (xdist's controller
# sets it first). JAXSPLIT_TEST_JAX_CACHE="" turns it off.
if "JAXSPLIT_TEST_JAX_CACHE" not in os.environ:
    import tempfile

    os.environ["JAXSPLIT_TEST_JAX_CACHE"] = tempfile.mkdtemp(prefix="jaxsplit-tests-jax-cache-")
if os.environ["JAXSPLIT_TEST_JAX_CACHE"]:
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.environ["JAXSPLIT_TEST_JAX_CACHE"])
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")

# XLA's CPU compiler emits each fused operation through its MLIR fusion emitters by default: an MLIR
# context and pass pipeline per fusion, the largest share of the suite's compile time. Its legacy
# LLVM emitter (xla_cpu_use_fusion_emitters=false) took the suite from 1274 to 914 s of CPU and 727
# to 535 s wall (2026-11-27); one LLVM module per program instead of one per thread (the workers
# fill both cores already) 5-9 % less CPU again (test_adjoints + test_core_stepper: 128 -> 116 and
# 124 -> 120 s). Programs whose bits the suite compares with users' ones compile with USERS_XLA
# instead (per program: ``.compile(compiler_options=USERS_XLA)``; in a child: ``users_env``).
# XLA aborts on a flag it does not know, so only on the JAX series it was measured on (pyproject pins it).
TEST_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false --xla_cpu_parallel_codegen_split_count=1"
USERS_XLA = {"xla_cpu_use_fusion_emitters": True}
if importlib.metadata.version("jaxlib").startswith("0.10.") and "fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()


def with_test_xla_flags(flags: str = "") -> str:
    """``XLA_FLAGS`` for a child process that sets flags of its own: those and the suite's."""
    return f"{flags} {TEST_XLA_FLAGS}".strip() if TEST_XLA_FLAGS in os.environ.get("XLA_FLAGS", "") else flags


def users_env(env: dict) -> dict:
    """``env`` without the suite's compiler switches: a child compiles as users' programs do."""
    flags = env.get("XLA_FLAGS", "").replace(TEST_XLA_FLAGS, "").strip()
    return {k: v for k, v in env.items() if k != "XLA_FLAGS"} | ({"XLA_FLAGS": flags} if flags else {}) \
        | {"JAX_DISABLE_MOST_OPTIMIZATIONS": "0"}


import jax  # after the switches above: JAX reads them when it starts
import pytest

jax.config.update("jax_enable_x64", True)

ROOT = pathlib.Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session", autouse=True)
def sigint_at_default_for_the_session():
    """The signal tests act as a user at a terminal (``signal_harness.sigint_at_default``);
    that SIGINT stays ignored where it starts ignored has a test of its own."""
    from signal_harness import sigint_at_default

    with sigint_at_default():
        yield


def docs_hooks():
    """``docs/hooks.py`` (the site's generated pages and the notebook executor) as a module."""
    spec = importlib.util.spec_from_file_location("jaxsplit_docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def executed_notebooks(tmp_path_factory):
    """Every notebook executed once per session at reduced size, all at once, into a folder
    ``notebooks``: (folder, {name: (exit code, stderr)}). The notebook test checks the runs;
    the docs build renders the executed copies instead of executing them again."""
    hooks = docs_hooks()
    out = tmp_path_factory.mktemp("executed") / "notebooks"
    return out, hooks.execute_notebooks(hooks.NOTEBOOKS, out)


LONGEST_FIRST = {"notebooks"}  # groups handed out before all others (see below)


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(items):
    """Whole files to one worker (``--dist loadgroup``): a file's tests share its module fixtures
    and the programs JAX has compiled for them, which a worker otherwise builds again. Tests with
    an ``xdist_group`` of their own (shared across files, or a heavy file split) keep it."""
    for item in items:
        if not item.get_closest_marker("xdist_group"):
            item.add_marker(pytest.mark.xdist_group(item.path.stem))
    # The order in which xdist hands the groups out (pyproject.toml: --no-loadscope-reorder, so it
    # is this one): the longest chains first, so that no worker starts one while the other has
    # nothing left (the wall time is the longest worker's). The notebook group runs the notebooks
    # (five kernels at once) and then the site build; the rest by their number of tests, largest
    # first (xdist's own order), every group's tests in their collected order.
    group = {item: item.get_closest_marker("xdist_group").args[0] for item in items}
    sizes = {}
    for name in group.values():
        sizes[name] = sizes.get(name, 0) + 1
    items.sort(key=lambda item: (group[item] not in LONGEST_FIRST, -sizes[group[item]], group[item]))
