"""The rotation form an accelerator's loops use (``core._loops.select_form``): the stack form,
where the CPU's loops use the select form. Run here on the CPU by forcing it: every system,
output mode and adjoint gives the same numbers in both forms, and the forced program holds
no select in its loop (``core/_loops.py``'s docstring says why the forms differ)."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.core._loops import _selecting, select_form

SAME = 1e-13  # the two forms run the same arithmetic; only the fused-multiply-add choices may differ

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
    "spin lattice": (lambda: jaxsplit.splitting(jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 8),
                                                                      field=(0.0, 0.0, 0.3)),
                                                "strang", "bonds"),
                     jnp.asarray(rng.standard_normal((8, 3)))),
}


def _both(fn):
    """``fn()`` with the select form and with the stack form, each traced afresh (the form is
    read while tracing, so cached programs must not be reused)."""
    out = []
    for form in (True, False):
        jax.clear_caches()
        with select_form(form):
            out.append(jax.tree.leaves(jax.block_until_ready(fn())))
    jax.clear_caches()
    return out


def test_the_cpu_uses_the_select_form_and_an_accelerator_the_stack_form():
    assert _selecting() is (jax.default_backend() == "cpu")
    with select_form():
        assert _selecting() is True
    with select_form(False):
        assert _selecting() is False


@pytest.mark.parametrize("system", list(CASES))
def test_both_forms_give_the_same_numbers(system):
    build, x0 = CASES[system]
    step = build()
    ts = jnp.linspace(0.0, 0.7, 4)
    batch = jax.tree.map(lambda a: jnp.stack([a, 0.9 * a]), x0)

    def runs():  # kept states, the final one, and a batch added by vmap; output at given times once
        out = (jaxsplit.integrate(step, x0, 0.05, 9, save_every=3).x,
               jax.jit(jax.vmap(lambda x: jaxsplit.integrate(step, x, 0.05, 9).final))(batch))
        return out + ((jaxsplit.integrate(step, x0, 0.05, ts=ts).x,) if system == "free body" else ())

    select, stack = _both(runs)
    assert [a.shape for a in stack] == [a.shape for a in select]
    assert max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(stack, select)) <= SAME


@pytest.mark.parametrize("adjoint", ["store", "reversible"])
def test_both_forms_give_the_same_gradients(adjoint):
    def loss(inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
        return jnp.sum(jaxsplit.integrate(step, M, 0.05, 40, adjoint=adjoint).final[:, 0] ** 2)

    select, stack = _both(lambda: jax.jit(jax.grad(loss))(INERTIA))
    scale = float(np.max(np.abs(np.asarray(select[0]))))
    assert float(np.max(np.abs(np.asarray(stack[0]) - np.asarray(select[0])))) <= SAME * max(scale, 1.0)


def test_each_form_writes_the_components_its_way_in_the_loop():
    """The loop bodies of the free body's program: components written by selects with the select
    form (the CPU's default), by concatenates with the stack form (the accelerator's)."""
    step = CASES["free body"][0]()

    def loop_selects(form):
        jax.clear_caches()
        with select_form(form):
            closed = jax.make_jaxpr(lambda y: jaxsplit.integrate(step, y, 0.05, 9).final)(M)
        jax.clear_caches()
        counts = {"select_n": 0, "concatenate": 0, "stack": 0, "loops": 0}  # jnp.stack: either primitive

        def walk(jaxpr, in_loop):
            for eqn in jaxpr.eqns:
                looping = in_loop or eqn.primitive.name in ("scan", "while")
                counts["loops"] += eqn.primitive.name in ("scan", "while")
                if in_loop and eqn.primitive.name in counts:
                    counts[eqn.primitive.name] += 1
                for value in eqn.params.values():
                    for sub in value if isinstance(value, (tuple, list)) else (value,):
                        sub = getattr(sub, "jaxpr", sub)
                        if hasattr(sub, "eqns"):
                            walk(sub, looping)

        walk(closed.jaxpr, False)
        return counts

    select, stack = loop_selects(True), loop_selects(False)
    assert select["loops"] and stack["loops"]
    # the select form writes a rotation's components by selects; the stack form by concatenates
    assert select["concatenate"] + select["stack"] == 0 and stack["concatenate"] + stack["stack"] > 0
    assert select["select_n"] > stack["select_n"]
