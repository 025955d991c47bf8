"""Poisson / symplectic / coadjoint-orbit checks, each on maps that must pass and must fail.

Acceptance 1: every splitting scheme of the core is Poisson to POISSON_TOL at random unit
states and h in [1e-3, 1]; explicit Euler and RK4 on the rigid body are exposed at h = 0.1,
and their defects grow like h² and h⁵ (the O(h) part of Euler's defect vanishes because
the vector field is Hamiltonian; RK4's local error is O(h⁵)).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import (
    STANDARD_CASE,
    RigidBody,
    explicit_euler,
    gauss_legendre,
    hat,
    orbit_symplectic_defect,
    poisson_defect,
    poisson_summary,
    rk4,
    roll,
    ruth,
    symplectic_defect,
    symplectic_summary,
)
from jaxsplit.checks._poisson import growth_exponent, random_unit_states

POISSON_TOL = 1e-12
EULER_FLOOR = 1e-4  # explicit Euler at h = 0.1 (measured ~5e-3)
RK4_FLOOR = 1e-10  # RK4 at h = 0.1 (measured ~1e-8): far above round-off
GROWTH_TOL = 0.15
SCAN_EQUIV_TOL = 1e-14  # scanned word vs the composition's unrolled call
SYMPLECTIC_TOL = 1e-14
N_SAMPLES = 64

BODY = RigidBody(jnp.array(STANDARD_CASE.inertia), allow_nonphysical=True)
STATES = random_unit_states(jax.random.PRNGKey(3), N_SAMPLES)
STEPS = jnp.exp(jax.random.uniform(jax.random.PRNGKey(4), (N_SAMPLES,), minval=np.log(1e-3), maxval=0.0))


def _compositions(body):
    out = []
    for name in jaxsplit.schemes:
        for split in ("axes", "casimir"):
            try:
                out.append((name, split, jaxsplit.splitting(body, name, split)))
            except jaxsplit.InputError:  # partitioned schemes need two pieces
                pass
    return out


def test_every_core_scheme_is_poisson():
    comps = _compositions(BODY)
    length = max(len(c.word) for *_, c in comps)
    @jax.jit  # one compilation for every scheme of a split: the word is data
    def measure(step):
        worst = jax.vmap(lambda x, h: poisson_defect(step, hat, x, h))(STATES, STEPS).max()
        return worst, step(STATES[0], 0.7)

    for name, split, comp in comps:
        worst, value = measure(roll(comp, length))
        gap = float(jnp.max(jnp.abs(comp(STATES[0], 0.7) - value)))  # the composition itself, unrolled
        assert gap <= SCAN_EQUIV_TOL, (name, split, gap)
        assert float(worst) <= POISSON_TOL, (name, split)
    assert len(comps) >= 2 * len(jaxsplit.schemes) - 4


def test_unscanned_composition_directly_on_the_paper_body():
    step = jaxsplit.splitting(RigidBody(jnp.array(jaxsplit.PAPER_BODY)), "lie-trotter")
    summary = poisson_summary(step, hat, STATES, STEPS)
    assert summary.max <= POISSON_TOL


@pytest.mark.parametrize("make,floor,exponent", [(explicit_euler, EULER_FLOOR, 2.0), (rk4, RK4_FLOOR, 5.0)])
def test_non_poisson_maps_are_exposed(make, floor, exponent):
    step = make(BODY)
    summary = poisson_summary(step, hat, STATES, 0.1)
    assert summary.max >= floor
    hs = jnp.array([0.2, 0.1, 0.05, 0.025])
    defects = jax.jit(jax.vmap(lambda h: jax.vmap(lambda x: poisson_defect(step, hat, x, h))(STATES).max()))(hs)
    assert abs(growth_exponent(hs, defects) - exponent) <= GROWTH_TOL


def test_summary_reports_where_the_maximum_is():
    summary = poisson_summary(explicit_euler(BODY), hat, STATES, STEPS)
    assert summary.max == pytest.approx(float(np.max(summary.defects)), rel=0, abs=0)
    assert np.array_equal(summary.x, np.asarray(STATES[summary.index]))
    assert summary.h == pytest.approx(float(STEPS[summary.index]), rel=1e-15)
    again = float(jax.jit(lambda x, h: poisson_defect(explicit_euler(BODY), hat, x, h))(summary.x, summary.h))
    assert again == pytest.approx(summary.max, rel=1e-12)


def _pendulum_states():
    return jax.random.normal(jax.random.PRNGKey(5), (N_SAMPLES, 2))


def test_symplectic_defect_pass_and_fail():
    pendulum = ruth(potential=lambda q: -jnp.cos(q[0]))
    assert symplectic_summary(pendulum, _pendulum_states(), STEPS).max <= SYMPLECTIC_TOL
    gl2 = gauss_legendre(jaxsplit.canonical_system(lambda x: 0.5 * x[1] ** 2 - jnp.cos(x[0]), 2), 2)
    assert symplectic_summary(gl2, _pendulum_states(), 0.3).max <= SYMPLECTIC_TOL
    # explicit Euler on the oscillator: DΦ = I + hL, DΦᵀ J DΦ = (1 + h²) J exactly
    euler = explicit_euler(jaxsplit.harmonic_oscillator())
    hs = jnp.array([0.1, 0.5])
    got = jax.jit(jax.vmap(lambda h: symplectic_defect(euler, jnp.array([0.3, 0.4]), h)))(hs)
    assert float(jnp.max(jnp.abs(got / hs**2 - 1))) <= 1e-14


def test_poisson_defect_on_a_non_constant_structure():
    ex = jaxsplit.example_3_1(1.0, 2.0, 0.0)
    xs = jax.random.normal(jax.random.PRNGKey(6), (N_SAMPLES, 2))
    # every RK method is Poisson here (see the audit, ex3.1): must pass
    assert poisson_summary(explicit_euler(ex), ex.poisson_matrix, xs, 0.3).max <= POISSON_TOL
    # a map that is not: x2 -> x2 + h x2², det DΦ x2 != Φ_2 -> defect = h x2² exactly
    bad = lambda x, h: jnp.array([x[0], x[1] + h * x[1] ** 2])
    summary = poisson_summary(bad, ex.poisson_matrix, xs, 0.3)
    assert summary.max == pytest.approx(float(jnp.max(0.3 * xs[:, 1] ** 2)), rel=1e-13)


def test_orbit_symplectic_defect_pass_and_fail():
    lt = jaxsplit.splitting(jaxsplit.RigidBody(jnp.array(jaxsplit.PAPER_BODY)), "lie-trotter")
    d = jax.jit(jax.vmap(lambda x, h: orbit_symplectic_defect(lt, x, h)))
    assert float(jnp.max(d(2.0 * STATES, STEPS))) <= SYMPLECTIC_TOL
    # RK4 projected back to the sphere keeps |m| but not the area form
    rk = rk4(BODY)
    projected = lambda m, h: rk(m, h) * jnp.linalg.norm(m) / jnp.linalg.norm(rk(m, h))
    e = jax.jit(jax.vmap(lambda x, h: orbit_symplectic_defect(projected, x, h)))
    assert float(jnp.max(e(STATES, jnp.full(N_SAMPLES, 0.5)))) >= 1e-6


def test_checks_follow_dtype_and_reject_bad_input():
    x32 = STATES[0].astype(jnp.float32)
    lt = jaxsplit.splitting(BODY, "strang")
    assert jax.jit(lambda x: poisson_defect(lt, hat, x, 0.1))(x32).dtype == jnp.float32  # eager: 5x the CPU
    with pytest.raises(jaxsplit.InputError, match="single state"):
        poisson_defect(lt, hat, STATES, 0.1)
    with pytest.raises(jaxsplit.InputError, match="one step size per state"):
        poisson_summary(lt, hat, STATES, jnp.ones(3))
    with pytest.raises(jaxsplit.InputError, match="even dimension"):
        symplectic_defect(lambda x, h: x, jnp.ones(3), 0.1)
