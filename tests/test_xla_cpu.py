"""XLA's small-loop setting (``jaxsplit._xla_cpu``): how ``XLA_FLAGS`` is extended, when it is
left alone, and that jaxsplit's loops then compile to one kernel (and 10⁵ bodies do not); the
per-program vector width: where it is passed, where not, and that results do not change."""

import jax
import jax.numpy as jnp
import pytest

import jaxsplit
from jaxsplit import _xla_cpu
from jaxsplit._xla_cpu import OPTION, SMALL_LOOP_BYTES, apply_small_loops, threshold_in, with_small_loops

SETTING = f"{OPTION}={SMALL_LOOP_BYTES}"
ROUNDOFF = 1e-13  # another kernel or layout: the same map, rounded differently (50 steps of 2 rotations)


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


# ------------------------------------------------------------------ vector width, per program
def test_compiler_options_widen_vectors_on_the_cpu_unless_the_user_sets_the_width(monkeypatch):
    expected = {_xla_cpu.VECTOR_OPTION: _xla_cpu.VECTOR_BITS} if jax.default_backend() == "cpu" else {}
    assert jaxsplit.compiler_options() == expected
    _xla_cpu.compiler_options.cache_clear()
    monkeypatch.setenv("XLA_FLAGS", f"--a=1 --{_xla_cpu.VECTOR_OPTION}=256")
    try:
        assert _xla_cpu.compiler_options() == {}
    finally:
        monkeypatch.undo()
        _xla_cpu.compiler_options.cache_clear()


def test_the_options_go_to_top_level_programs_only(monkeypatch):
    """JAX refuses compiler options on a jit nested in any trace: the wrapper passes them at top
    level and leaves them out under jit, grad and vmap."""
    seen = []
    real = jax.jit
    monkeypatch.setattr(jax, "jit", lambda f, **kw: seen.append(kw.get("compiler_options")) or real(f, **kw))
    double = _xla_cpu.jit(lambda x: 2 * x)
    assert float(double(jnp.asarray(1.0))) == 2.0
    assert float(real(double)(jnp.asarray(1.0))) == 2.0
    assert float(jax.grad(double)(jnp.asarray(1.0))) == 2.0
    assert jax.vmap(double)(jnp.ones(3)).tolist() == [2.0, 2.0, 2.0]
    assert seen == [jaxsplit.compiler_options() or None, None]  # built once per context


def test_integrate_runs_in_every_context_and_the_width_leaves_results_bit_identical():
    body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]))
    m0 = jax.random.normal(jax.random.PRNGKey(0), (64, 3))
    step = jaxsplit.splitting(body, "strang", "casimir")
    fast = step.for_run(m0, 0.1)  # what integrate runs: the polynomial kernel, components first
    run = lambda m: fast.advance(m, 0.1, 50)
    wide = jax.jit(run, compiler_options=jaxsplit.compiler_options() or None)(m0)
    assert bool(jnp.all(wide == jax.jit(run)(m0)))  # elementwise code: wider vectors, same rounding
    assert bool(jnp.all(jaxsplit.integrate(step, m0, 0.1, 50).final == wide))
    nested = jax.jit(lambda m: jaxsplit.integrate(step, m, 0.1, 50).final)(m0)  # traced: the general kernel
    per_state = jax.vmap(lambda m: jaxsplit.integrate(step, m, 0.1, 50).final)(m0)
    grad = jax.grad(lambda m: jnp.sum(jaxsplit.integrate(step, m, 0.1, 50).final ** 2))(m0)
    for other in (nested, per_state):
        assert float(jnp.max(jnp.abs(other - wide))) <= ROUNDOFF
    assert float(jnp.max(jnp.abs(grad - 2 * m0))) <= 10 * ROUNDOFF  # |m| is conserved: d|m(T)|²/dm0 = 2 m0 (|m0| to 3)
