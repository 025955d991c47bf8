"""The stepping loop as one CPU kernel (``jaxsplit.core._one_kernel``): tagged where it pays
and can compile, untagged otherwise, the same results either way."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import USERS_XLA

import jaxsplit
from jaxsplit.core import _one_kernel

OURS = 'inlineable="false"'  # XLA's own small-loop pass tags xla_cpu_small_call alone


def states(b):
    m = np.random.default_rng(1).standard_normal((b, 3))
    return jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True))


@pytest.fixture
def limit():
    """Set ``ONE_KERNEL_BYTES`` for the test (read when a program is lowered: ``compiled``)."""
    def set_limit(value):
        _one_kernel.ONE_KERNEL_BYTES = value

    default = _one_kernel.ONE_KERNEL_BYTES
    yield set_limit
    set_limit(default)


def _compile(fn, *args, **options):
    """``fn`` jitted as a new function: traced, lowered and compiled anew (no cached program
    from another limit; clearing JAX's caches instead cost the worker's other tests theirs)."""
    return jax.jit(lambda *a: fn(*a)).lower(*args).compile(compiler_options=options)


def compiled(fn):
    """``fn`` compiled anew, with XLA's CPU emitters as users compile: the suite's own switch
    (``conftest``) emits the untagged loop otherwise than the one kernel, equal only to round-off."""
    return lambda *args: _compile(fn, *args, **USERS_XLA)(*args)


def program(fn, *args):
    return _compile(fn, *args).as_text()


def free_run(scheme, b, n=300, h=0.3):
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    x0 = states(b)
    step = jaxsplit.splitting(body, scheme, "casimir")
    return (lambda x: jaxsplit.integrate(step, x, h, n).final), x0


@pytest.mark.parametrize("scheme", ["strang", "blanes-casas-murua-8"])
def test_a_batch_under_the_limit_runs_tagged_and_equal_to_the_untagged_loop(limit, scheme):
    run, x0 = free_run(scheme, 256)
    text = program(run, x0)
    assert OURS in text
    assert not any("pred[" in state for state in re.findall(r"= \(([^)]*)\) while\(", text))  # tests kept inside
    tagged = compiled(run)(x0)
    limit(-1)
    assert OURS not in program(run, x0)
    np.testing.assert_array_equal(np.asarray(compiled(run)(x0)), np.asarray(tagged))  # measured bit-identical


def test_the_limit_counts_the_state_as_lowered_vmapped_batches_included(limit):
    limit(4 * 2**10)  # 170 float64 bodies
    small, x_small = free_run("strang", 128)
    large, x_large = free_run("strang", 256)
    assert OURS in program(small, x_small) and OURS not in program(large, x_large)
    group, x_group = free_run("strang", 64)  # 1.5 KiB a group: vmapped over 2 groups, 3 KiB; over 16, 24 KiB
    batched = jax.vmap(group)
    assert OURS in program(batched, jnp.stack([x_group] * 2)) and OURS not in program(batched, jnp.stack([x_group] * 16))


def test_one_body_and_a_vmapped_batch_are_tagged_like_a_batch():
    """The decision is taken where the shapes are final: one body's loop (XLA's own pass, at its
    default 1 KiB, leaves a long scheme's loop as thunks) and 256 bodies arriving by ``vmap``
    (each seen as one body while tracing) are tagged."""
    run, x0 = free_run("blanes-casas-murua-8", 1)
    assert OURS in program(run, x0)
    batch, xs = free_run("kahan-li-8", 256)
    one = lambda x: batch(x)
    assert OURS in program(jax.vmap(one), xs)


def shear_flows(write):
    """Two exact shears of (q, p) (each of shape (128,): 2 KiB a state, above the floor),
    written with ``write(x, k, value)``."""
    return [lambda x, t: write(x, 0, x[0] + t * x[1]), lambda x, t: write(x, 1, x[1] - t * x[0])]


WRITES = {
    "stack (tagged)": lambda x, k, v: jnp.stack([v if i == k else x[i] for i in range(2)]),
    "scatter": lambda x, k, v: x.at[k].set(v),
    "dot": lambda x, k, v: x + jnp.eye(2, dtype=x.dtype)[:, k:k + 1] @ (v - x[k])[None],
    "sort": lambda x, k, v: jnp.stack([v if i == k else x[i] for i in range(2)]) + 0 * jnp.sort(x)[0],
    "custom call (solve)": lambda x, k, v: jnp.linalg.solve(jnp.eye(2, dtype=x.dtype),
                                                             jnp.stack([v if i == k else x[i] for i in range(2)])),
}


@pytest.mark.parametrize("kind", list(WRITES))
def test_a_loop_with_an_operation_the_kernel_emitter_refuses_runs_untagged_and_right(kind):
    step = jaxsplit.compose(shear_flows(WRITES[kind]), "strang")
    x0, h, n = jnp.array([[1.0] * 128, [0.0] * 128]), 0.01, 400

    def run(x):
        return jaxsplit.integrate(step, x, h, n).final

    assert (OURS in program(run, x0)) == (kind == "stack (tagged)")
    expected = np.array([1.0, 0.0])
    for _ in range(n):  # Strang: half shear of q, shear of p, half shear of q
        expected[0] += h / 2 * expected[1]
        expected[1] -= h * expected[0]
        expected[0] += h / 2 * expected[1]
    np.testing.assert_allclose(np.asarray(jax.jit(run)(x0)), np.repeat(expected[:, None], 128, 1), rtol=0, atol=1e-13)


def test_other_backends_never_get_the_tag():
    run, x0 = free_run("blanes-casas-murua-8", 256)
    for platform, tagged in (("cpu", True), ("cuda", False)):
        text = jax.export.export(jax.jit(run), platforms=[platform])(x0).mlir_module()
        assert ("xla_cpu_small_call" in text) == tagged, platform


def test_the_reversible_gradient_runs_its_backward_pass_tagged_and_matches_the_untagged_one(limit):
    def loss(inertia):  # the backward pass (stepping back) is a loop of its own
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
        return jnp.sum(jaxsplit.integrate(step, states(64), 0.05, 500, adjoint="reversible").final ** 3)

    inertia = jnp.asarray(jaxsplit.STANDARD_CASE.inertia)
    assert OURS in program(jax.grad(loss), inertia)
    tagged = compiled(jax.grad(loss))(inertia)
    limit(-1)
    np.testing.assert_allclose(np.asarray(compiled(jax.grad(loss))(inertia)), np.asarray(tagged), rtol=1e-12)


def kahan_li_6(inertia):
    return jaxsplit.splitting(jaxsplit.RigidBody(inertia), "kahan-li-6", "casimir", shift=1)


TIMES = jnp.linspace(0.5, 5.0, 4)
# 256 bodies: components last, each rotation a select on constant component tests. A ts= run's
# reversible gradient uses both loops below (measured 10x slower before; 5 s to compile here).
ENTRY_POINTS = {
    "run": lambda i: jaxsplit.integrate(kahan_li_6(i), states(256), 0.05, 100).final,
    "ts= run": lambda i: jaxsplit.integrate(kahan_li_6(i), states(256), 0.05, ts=TIMES).x,
    "reversible gradient": jax.grad(lambda i: jnp.sum(
        jaxsplit.integrate(kahan_li_6(i), states(256), 0.05, 100, adjoint="reversible").final ** 3)),
}


@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_every_stepping_loop_keeps_the_select_tests_inside(entry):
    """Component tests that leave a loop enter its kernels as data, which then run as scalar
    code. Two ways they left, both measured: a nested loop call under differentiation (JAX's
    partial evaluation; Kahan–Li 8's reversible gradient on 256 bodies 4× slower) and a
    fori_loop's unchanged bound (XLA's invariant code motion; ts= runs 19× slower)."""
    text = program(ENTRY_POINTS[entry], jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    loop_states = re.findall(r"= \(([^)]*)\) while\(", text)
    assert loop_states and OURS in text
    assert not any("pred[" in state for state in loop_states)


def test_a_vmapped_state_of_parts_with_a_differentiated_kick_is_right():
    """Regression: XLA's one-kernel emitter compiled this loop wrongly under ``jit(vmap(...))``
    (a gravity-gradient Strang step, whose kick is ``jax.grad`` of a quadratic potential: 0.27
    apart from the direct call after 400 steps) while its loop held transposes; such loops now
    run untagged. Every call form must give the direct call's numbers."""
    inertia = jnp.array([2.0, 1.0, 2 / 3])
    system = jaxsplit.gravity_gradient(inertia, 0.5, allow_nonphysical=True)
    step = jaxsplit.splitting(system, "strang")
    rng = np.random.default_rng(0)
    gamma = rng.standard_normal((16, 3))
    x0 = (jnp.asarray(rng.standard_normal((16, 3))), jnp.asarray(gamma / np.linalg.norm(gamma, axis=1, keepdims=True)))
    run = lambda x: jaxsplit.integrate(step, x, 0.01, 60).final
    direct = run(x0)
    for form in (jax.jit(run), jax.jit(jax.vmap(run))):
        for a, b in zip(form(x0), direct):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-13)
