"""The bond split's fast path (``systems._spin_pairs``: pair flows by reshapes, components first)
against the gather path on the same lattice and colours: the same map to round-off, in every
polynomial tier and the full-range kernel; Casimirs, Poisson defect, layouts, dtypes, batches,
gradients; and where it does not apply.

The gather path of the same system is forced by giving the exchange one value per bond
(``pair_layout`` takes one shared J only).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.lattices import lattice
from jaxsplit.systems._spin_pairs import TIERS, LaidOut, PairExchange, _kernel, _pair_flow

ROUND_OFF = 1e-13
SITE_TERMS = {"field": (0.1, -0.2, 0.3), "anisotropy": 0.4, "axis": (1.0, 1.0, 1.0)}
CASES = [("chain", 8), ("square", (4, 6)), ("simple-cubic", 4)]


def _pair(name, size, **terms):
    lat = lattice(name, size)
    fast = jaxsplit.spin_lattice(lat, exchange=0.8, spin_length=1.3, **terms)
    gather = jaxsplit.spin_lattice(lat, exchange=np.full(lat.n_bonds, 0.8), spin_length=1.3, **terms)
    return fast, gather


@pytest.mark.parametrize("name, size", CASES)
def test_fast_path_is_the_gather_path_to_round_off(name, size):
    fast, gather = _pair(name, size, **SITE_TERMS)
    step, reference = (jaxsplit.splitting(s, "strang", "bonds") for s in (fast, gather))
    assert isinstance(step, LaidOut) and type(reference) is jaxsplit.Composition
    assert sum(isinstance(f, PairExchange) for f in step.flows) == 2 * fast.lattice.dimension
    s0 = fast.random_state(seed=3)
    # one step at step sizes in every tier and beyond the last (the full-range kernel):
    # bound 2 |J h| max s_i = 2.08 h
    fast_step, gather_step = jax.jit(step), jax.jit(reference)
    for h in (0.01, 0.1, 0.5, 1.2):
        assert float(jnp.max(jnp.abs(fast_step(s0, h) - gather_step(s0, h)))) < ROUND_OFF, h
    assert 2.08 * 1.2 > TIERS[-1]
    # a short run (the first-same-as-last loop) and the lattice-shaped state
    run = jaxsplit.integrate(step, s0, 0.05, 30).final
    assert float(jnp.max(jnp.abs(run - jaxsplit.integrate(reference, s0, 0.05, 30).final))) < ROUND_OFF
    shaped = s0.reshape(fast.lattice.shape + (3,))
    out = jaxsplit.integrate(step, shaped, 0.05, 30).final
    assert out.shape == shaped.shape and float(jnp.max(jnp.abs(out.reshape(-1, 3) - run))) < ROUND_OFF
    # each flow alone, on the user's layout, is the gather path's flow
    for f, g in zip(step.flows, reference.flows, strict=True):
        for t in (0.37, 4.0):
            assert float(jnp.max(jnp.abs(jax.jit(f)(s0, t) - jax.jit(g)(s0, t)))) < 1e-14


def test_the_closed_form_derivative_is_the_switchs_derivative():
    """The pair flow's JVP (closed form, ``_pair_flow_jvp``) against JAX differentiating the kernel
    itself, in the polynomial tier and the full-range kernel, both parities, with tangents in the
    state and in J t (what gradients in h and J see)."""
    x = jnp.asarray(np.random.default_rng(5).normal(size=(3, 8)))
    dx = jnp.asarray(np.random.default_rng(6).normal(size=(3, 8)))
    for parity in (0, 1):
        for jt, tier in ((0.3, 0), (2.9, len(TIERS))):
            kernel = lambda y, t, limit=(TIERS + (None,))[tier]: _kernel(y, t, 1, 0, parity, limit)
            flow = lambda y, t, tier=tier: _pair_flow(y, t, jnp.int32(tier), 1, 0, parity)
            (_, expected), (_, found) = (jax.jvp(f, (x, jt), (dx, 0.7)) for f in (kernel, flow))
            assert float(jnp.max(jnp.abs(found - expected))) <= ROUND_OFF * float(jnp.max(jnp.abs(expected))), (parity, tier)
            # must fail: the derivative of the other tier's polynomial where it does not apply
            if tier:
                wrong = jax.jvp(lambda y, t: _kernel(y, t, 1, 0, parity, TIERS[0]), (x, jt), (dx, 0.7))[1]
                assert float(jnp.max(jnp.abs(wrong - expected))) > 1e-6


def test_casimirs_and_poisson_defect_on_the_fast_path():
    # the Poisson defect (jacfwd of the step) on the chain: the same pair kernel and site flows as
    # on the cube, a fraction of its compilation (63 s of CPU on the cube, most of this file's)
    chain, _ = _pair("chain", 8, **SITE_TERMS)
    s0 = chain.random_state(seed=1)
    assert float(jaxsplit.poisson_defect(jaxsplit.splitting(chain, "strang", "bonds"), chain, s0, 0.2)) < ROUND_OFF
    fast, _ = _pair("simple-cubic", 4, **SITE_TERMS)
    step = jaxsplit.splitting(fast, "strang", "bonds")
    s0 = fast.random_state(seed=1)
    x = jaxsplit.integrate(step, s0, 0.05, 2000).final
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) / 1.3 - 1))) < ROUND_OFF


def test_schemes_batches_dtypes_and_gradients():
    # the long words on the chain (the composition is generic; every axis's pair kernel is checked by
    # test_fast_path_is_the_gather_path_to_round_off): on the square they took ~70 s of CPU to compile
    fast, gather = _pair("chain", 8)
    s0 = fast.random_state(seed=2)
    for scheme in ("yoshida-6a", "kahan-li-8"):
        a = jaxsplit.integrate(jaxsplit.splitting(fast, scheme, "bonds"), s0, 0.1, 5).final
        b = jaxsplit.integrate(jaxsplit.splitting(gather, scheme, "bonds"), s0, 0.1, 5).final
        assert float(jnp.max(jnp.abs(a - b))) < ROUND_OFF
    fast, gather = _pair("square", 4)
    s0 = fast.random_state(seed=2)
    step = jaxsplit.splitting(fast, "strang", "bonds")
    batch = jnp.stack([s0, fast.random_state(seed=4)])
    out = jaxsplit.integrate(step, batch, 0.1, 4).final
    one = jax.vmap(lambda x: jaxsplit.integrate(step, x, 0.1, 4).final)(batch)
    assert out.shape == batch.shape and float(jnp.max(jnp.abs(out - one))) < ROUND_OFF
    single = jaxsplit.integrate(step, s0.astype(jnp.float32), 0.1, 4).final
    assert single.dtype == jnp.float32 and float(jnp.max(jnp.abs(single - out[0]))) < 1e-5

    # gradients on the chain: the same pair kernel reversed, half the flows of the square (its
    # gradients took 48 s of CPU each to trace and compile, two thirds of this file's time)
    fast, gather = _pair("chain", 8)
    s0 = fast.random_state(seed=2)
    step = jaxsplit.splitting(fast, "strang", "bonds")
    assert isinstance(step, LaidOut)

    def loss(x0, adjoint):
        return jnp.sum(jaxsplit.integrate(step, x0, 0.1, 6, adjoint=adjoint).final[:, 2])

    grads = [jax.grad(loss)(s0, a) for a in ("store", "reversible")]
    reference = jax.grad(lambda x0: jnp.sum(jaxsplit.integrate(jaxsplit.splitting(gather, "strang", "bonds"), x0,
                                                               0.1, 6).final[:, 2]))(s0)
    for g in grads:
        assert float(jnp.max(jnp.abs(g - reference))) < 1e-12


@pytest.mark.parametrize("name, size, terms", [
    ("chain", 7, {}),                                   # odd length: Δ + 1 colours
    ("square", 4, {"dm": (0.0, 0.0, 0.2)}),             # DM
    ("square", 4, {"anisotropic": 0.3}),                # XXZ
    ("honeycomb", 2, {}),                               # not hypercubic
])
def test_gather_path_where_the_fast_path_does_not_apply(name, size, terms):
    system = jaxsplit.spin_lattice(lattice(name, size), **terms)
    assert system.pair_layout() is None
    assert type(jaxsplit.splitting(system, "strang", "bonds")) is jaxsplit.Composition
    assert jaxsplit.spin_lattice(lattice("square", 4, periodic=False)).pair_layout() is None
