"""The loop layout an accelerator uses (``core._loops.laid_out``): states carried components
first inside jaxsplit's loops. Run here on the CPU by forcing it (``components_first``): every
system, output mode and adjoint gives the components-last run's numbers, and the CPU's own
default stays components last (its select form, ``core/_loops.py``'s docstring)."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.core._loops import components_first, laid_out

SAME = 1e-13  # the two layouts run the same arithmetic; only the fused-multiply-add choices may differ

rng = np.random.default_rng(7)
M = jnp.asarray(rng.standard_normal((5, 3)))
GAMMA = jnp.asarray(rng.standard_normal((5, 3)))
GAMMA = GAMMA / jnp.linalg.norm(GAMMA, axis=-1, keepdims=True)
Q = jnp.broadcast_to(jnp.eye(3), (5, 3, 3))
INERTIA = jnp.array([2.0, 1.6, 1.0])
CASES = {
    "free body": (lambda: jaxsplit.splitting(jaxsplit.RigidBody(INERTIA), "kahan-li-6", "casimir"), M),
    "heavy top": (lambda: jaxsplit.splitting(jaxsplit.heavy_top(INERTIA, jnp.array([0.0, 0.1, 0.4]), 1.3), "strang"),
                  (M, GAMMA)),
    "attitude": (lambda: jaxsplit.splitting(jaxsplit.attitude(INERTIA), "strang"), (M, Q)),
    "spin lattice": (lambda: jaxsplit.splitting(jaxsplit.spin_lattice(jaxsplit.lattices.lattice("square", 4),
                                                                      field=(0.0, 0.0, 0.3)),
                                                "strang", "bonds"),
                     jnp.asarray(rng.standard_normal((16, 3)))),
}


def _both(fn):
    """``fn()`` components last and components first, each traced afresh (the layout is read
    while tracing, so cached programs must not be reused)."""
    out = []
    for first in (False, True):
        jax.clear_caches()
        with components_first(first):
            out.append(jax.tree.leaves(jax.block_until_ready(fn())))
    jax.clear_caches()
    return out


def test_the_cpu_carries_components_last_by_default():
    assert jax.default_backend() != "cpu" or laid_out() is False
    with components_first():
        assert laid_out() is True
    with components_first(False):
        assert laid_out() is False


@pytest.mark.parametrize("system", list(CASES))
def test_components_first_runs_give_the_same_numbers(system):
    build, x0 = CASES[system]
    step = build()
    ts = jnp.linspace(0.0, 0.7, 4)
    batch = jax.tree.map(lambda a: jnp.stack([a, 0.9 * a]), x0)

    def runs():  # kept states, the final one, and a batch added by vmap; output at given times once
        out = (jaxsplit.integrate(step, x0, 0.05, 9, save_every=3).x,
               jax.jit(jax.vmap(lambda x: jaxsplit.integrate(step, x, 0.05, 9).final))(batch))
        return out + ((jaxsplit.integrate(step, x0, 0.05, ts=ts).x,) if system == "free body" else ())

    last, first = _both(runs)
    assert [a.shape for a in first] == [a.shape for a in last]
    assert max(float(np.max(np.abs(np.asarray(a) - np.asarray(b))))for a, b in zip(first, last)) <= SAME


@pytest.mark.parametrize("adjoint", ["store", "reversible"])
def test_components_first_gradients_are_the_same(adjoint):
    def loss(inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
        return jnp.sum(jaxsplit.integrate(step, M, 0.05, 40, adjoint=adjoint).final[:, 0] ** 2)

    last, first = _both(lambda: jax.jit(jax.grad(loss))(INERTIA))
    scale = float(np.max(np.abs(np.asarray(last[0]))))
    assert float(np.max(np.abs(np.asarray(first[0]) - np.asarray(last[0])))) <= SAME * max(scale, 1.0)


def test_components_first_splits_the_loop_state_and_not_a_laid_out_spin_state():
    """Forced, the free body's loop carries one (B,) array per component (the default carries
    (B, 3) only); the spin fast path's ``Components`` (already components first, (3, 4, 4))
    is carried as it is, never as rows of its (16, 3) user state."""
    free = CASES["free body"][0]()
    spins, s0 = CASES["spin lattice"][0](), CASES["spin lattice"][1]

    def program(step, x):
        return str(jax.make_jaxpr(lambda y: jaxsplit.integrate(step, y, 0.05, 9).final)(x))

    jax.clear_caches()
    plain = program(free, M)
    with components_first():
        jax.clear_caches()
        forced, spin = program(free, M), program(spins, s0)
    jax.clear_caches()
    rows = re.compile(r"\w+:f64\[5\] \w+:f64\[5\] \w+:f64\[5\]")  # a loop body's three component arguments
    assert rows.search(forced) and not rows.search(plain)
    assert "f64[3,4,4]" in spin and not re.search(r"\w+:f64\[16\] \w+:f64\[16\] \w+:f64\[16\]", spin)
