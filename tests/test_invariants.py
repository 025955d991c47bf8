"""Invariant monitors: exact values on synthetic trajectories, then must-pass / must-fail
cases on real integrations (a splitting keeps C to round-off; explicit Euler does not)."""

import jax.numpy as jnp
import pytest

import jaxsplit
from jaxsplit import STANDARD_CASE, RigidBody, integrate, invariant_errors, monitor_invariants

DRIFT_TOL = 1e-12  # least-squares slope of exactly linear data
CASIMIR_TOL = 1e-13  # splitting, relative, 1e4 steps
EULER_CASIMIR_FLOOR = 1e-2  # explicit Euler: |m|² grows by h²|f|² each step
BOUNDED_DRIFT = 1e-8  # Strang energy error over T = 1000: bounded, no secular slope

BODY = RigidBody(jnp.array(STANDARD_CASE.inertia), allow_nonphysical=True)
M0 = jnp.array(STANDARD_CASE.m0)


def test_synthetic_linear_drift_and_oscillation():
    t = jnp.linspace(0.0, 100.0, 1001)
    xs = jnp.stack([1.0 + 0.01 * t, jnp.zeros_like(t)], axis=1)
    err = invariant_errors(lambda x: x[0], xs, times=t)
    assert float(err.drift) == pytest.approx(0.01, abs=DRIFT_TOL)
    assert float(err.max_absolute) == pytest.approx(1.0, abs=1e-12)
    assert float(err.max_relative) == pytest.approx(1.0, abs=1e-12)
    assert float(err.final) == pytest.approx(1.0, abs=1e-12)
    # a periodic error over whole periods has no drift (must fail the drift test above)
    osc = jnp.stack([1.0 + 0.01 * jnp.sin(2 * jnp.pi * t / 10.0), t], axis=1)
    err = invariant_errors(lambda x: x[0], osc, times=t)
    assert abs(float(err.drift)) <= 0.01 / 100  # ~2e-5: two orders below the linear drift
    assert float(err.max_absolute) == pytest.approx(0.01, rel=1e-6)


def test_splitting_keeps_the_casimir_and_bounds_the_energy():
    traj = integrate(jaxsplit.splitting(BODY, "strang"), M0, 0.1, 10_000, save_every=10)
    errors = monitor_invariants(BODY, traj)
    assert set(errors) == {"energy", "casimir"}
    assert float(errors["casimir"].max_relative) <= CASIMIR_TOL
    assert float(errors["energy"].max_relative) >= 1e-6  # not energy preserving: must be seen
    assert abs(float(errors["energy"].drift)) <= BOUNDED_DRIFT


def test_explicit_euler_is_caught():
    traj = integrate(jaxsplit.explicit_euler(BODY), M0, 0.1, 1000, save_every=10)
    errors = monitor_invariants(jaxsplit.rigid_body_system(BODY), traj)
    assert set(errors) == {"energy", "casimir"}
    assert float(errors["casimir"].max_relative) >= EULER_CASIMIR_FLOOR
    assert float(errors["casimir"].drift) > 0  # |m| only grows


def test_bad_input():
    with pytest.raises(jaxsplit.InputError, match="Trajectory"):
        invariant_errors(lambda x: x[0], jnp.ones((3, 2)))
    with pytest.raises(jaxsplit.InputError, match="K times"):
        invariant_errors(lambda x: x[0], jnp.ones((3, 2)), times=jnp.ones(4))
    with pytest.raises(jaxsplit.InputError, match="no invariants"):
        monitor_invariants(object(), jnp.ones((3, 2)), times=jnp.ones(3))
