"""XLA's CPU tuning (``jaxsplit._xla_cpu``): nothing on import, an explicit ``tune_cpu()`` that
leaves the user's own setting alone, and per-program ``compiler_options()``."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp

import jaxsplit
from jaxsplit import _xla_cpu

ROUNDOFF = 1e-13
WIDE = f"--{_xla_cpu.VECTOR_OPTION}={_xla_cpu.VECTOR_BITS}"


def test_importing_jaxsplit_changes_no_global_state():
    """A fresh process: ``import jaxsplit`` (and loading its core) leaves ``XLA_FLAGS`` and JAX's
    configuration as they were."""
    code = ("import os, jax; before = (os.environ.get('XLA_FLAGS'), jax.config.jax_enable_x64); "
            "import jaxsplit, jaxsplit.core, jaxsplit.systems; "
            "assert (os.environ.get('XLA_FLAGS'), jax.config.jax_enable_x64) == before, before; print('ok')")
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_tune_cpu_adds_the_width_once_and_leaves_the_users_own_setting(monkeypatch):
    monkeypatch.setattr(_xla_cpu, "_backend_started", lambda: False)
    environ = {"XLA_FLAGS": "--a=1"}
    assert _xla_cpu.tune_cpu(environ).startswith("on") and environ["XLA_FLAGS"] == f"--a=1 {WIDE}"
    assert _xla_cpu.tune_cpu(environ).startswith("on") and environ["XLA_FLAGS"] == f"--a=1 {WIDE}"  # once
    own = {"XLA_FLAGS": f"--{_xla_cpu.VECTOR_OPTION}=256"}
    assert _xla_cpu.tune_cpu(own).startswith("yours") and own == {"XLA_FLAGS": f"--{_xla_cpu.VECTOR_OPTION}=256"}
    monkeypatch.setattr(_xla_cpu, "_backend_started", lambda: True)
    late = {}
    assert _xla_cpu.tune_cpu(late).startswith("off") and late == {}  # too late to take effect: nothing changed


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


def test_integrate_runs_in_every_context_and_the_width_leaves_results_bit_identical():
    body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]), allow_nonphysical=True)
    m0 = jax.random.normal(jax.random.PRNGKey(0), (64, 3))
    step = jaxsplit.splitting(body, "strang", "casimir")
    run = lambda m: jaxsplit.integrate(step, m, 0.1, 50).final
    wide = jax.jit(run, compiler_options=jaxsplit.compiler_options() or None)(m0)
    assert bool(jnp.all(wide == jax.jit(run)(m0)))  # elementwise code: wider vectors, same rounding
    assert bool(jnp.all(run(m0) == wide))
    per_state = jax.jit(jax.vmap(run))(m0)
    grad = jax.grad(lambda m: jnp.sum(run(m) ** 2))(m0)
    assert float(jnp.max(jnp.abs(per_state - wide))) <= ROUNDOFF
    assert float(jnp.max(jnp.abs(grad - 2 * m0))) <= 10 * ROUNDOFF  # |m| is conserved: d|m(T)|²/dm0 = 2 m0 (|m0| to 3)
