"""XLA's small-loop setting (``jaxsplit._xla_cpu``): how ``XLA_FLAGS`` is extended, when it is
left alone, and that jaxsplit's loops then compile to one kernel (and 10⁵ bodies do not)."""

import jax
import jax.numpy as jnp
import pytest

import jaxsplit
from jaxsplit import _xla_cpu
from jaxsplit._xla_cpu import OPTION, SMALL_LOOP_BYTES, apply_small_loops, threshold_in, with_small_loops

SETTING = f"{OPTION}={SMALL_LOOP_BYTES}"


@pytest.mark.parametrize("flags, expected", [
    ("", f"--xla_backend_extra_options={SETTING}"),
    ("--xla_force_host_platform_device_count=4",
     f"--xla_force_host_platform_device_count=4 --xla_backend_extra_options={SETTING}"),
    ("--xla_backend_extra_options=a=1", f"--xla_backend_extra_options=a=1,{SETTING}"),
    ("--xla_backend_extra_options=", f"--xla_backend_extra_options={SETTING}"),
    ("--xla_backend_extra_options=a=1 --x=2 --xla_backend_extra_options=b=2",  # XLA keeps the last one
     f"--xla_backend_extra_options=a=1 --x=2 --xla_backend_extra_options=b=2,{SETTING}"),
])
def test_the_setting_joins_the_users_flags(flags, expected):
    assert with_small_loops(flags) == expected


@pytest.mark.parametrize("flags", [f"--xla_backend_extra_options={OPTION}=1024",
                                   f"--a=1 --xla_backend_extra_options=b=2,{OPTION}=0"])
def test_a_users_own_threshold_is_left_alone(flags):
    assert with_small_loops(flags) is None
    environ = {"XLA_FLAGS": flags}
    assert apply_small_loops(environ).startswith("yours") and environ == {"XLA_FLAGS": flags}


def test_nothing_changes_once_the_backend_has_started(monkeypatch):
    monkeypatch.setattr(_xla_cpu, "_backend_started", lambda: True)
    environ = {}
    assert apply_small_loops(environ).startswith("off") and environ == {}
    monkeypatch.setattr(_xla_cpu, "_backend_started", lambda: False)
    assert apply_small_loops(environ).startswith("on") and environ == {"XLA_FLAGS": f"--xla_backend_extra_options={SETTING}"}


def _one_kernel(bodies: int) -> bool:
    m = jnp.ones((bodies, 3)) / jnp.sqrt(3.0)
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2 / 3])), "strang", "casimir").for_run(m, 0.01)
    compiled = jax.jit(lambda x: jaxsplit.integrate(step, x, 0.01, 10).final).lower(m).compile()
    return "xla_cpu_small_call" in compiled.as_text()


def test_the_threshold_is_read_back_from_the_flags():
    assert threshold_in(with_small_loops("--a=1")) == SMALL_LOOP_BYTES
    assert threshold_in(f"--xla_backend_extra_options={OPTION}=1 --xla_backend_extra_options={OPTION}=7") == 7
    assert threshold_in("--xla_backend_extra_options=a=1") is None and threshold_in("") is None
    assert apply_small_loops({"XLA_FLAGS": with_small_loops("")}).startswith("on")  # a child of a jaxsplit process


def test_small_loops_compile_to_one_kernel_and_large_batches_do_not():
    # conftest imports jaxsplit before JAX starts (xdist's workers inherit the parent's XLA_FLAGS)
    setting = jaxsplit.small_loop_setting()
    if setting.startswith("yours"):
        pytest.skip(f"XLA_FLAGS sets another threshold: the user's choice ({setting})")
    assert setting.startswith("on"), setting
    assert _one_kernel(256)
    assert not _one_kernel(100_000)  # one kernel would lose XLA's threads (benchmarks/results/small_loops.md)
