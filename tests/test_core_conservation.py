"""Acceptance 2 (core): the Casimir is conserved to round-off over 10^5 steps by every
scheme; Strang's energy error on the standard case is bounded with no drift on [0, 1e4]."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit

CASIMIR_RTOL = 1e-12
STRANG_ENERGY_BOUND = 5.45e-4  # shared/reference/rigid-body.md: <= 5.4e-4 (two digits)
DRIFT_TOL = 1e-3  # |fitted slope| * T relative to the maximum error

BODY = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)


# the same run as test_core_stepper.py's merge check: one compiled program on one xdist worker
@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.xdist_group(f"unrolled-{name}"))
                                  for name in jaxsplit.schemes])
def test_casimir_conserved_over_1e5_steps(name):
    split = "axes" if jaxsplit.schemes[name].pieces_allowed(3) else "casimir"
    traj = jaxsplit.integrate(jaxsplit.splitting(BODY, name, split), M0, 0.1, 100_000, save_every=100)
    casimir = np.asarray(BODY.casimir(traj.x))
    assert np.abs(casimir / casimir[0] - 1).max() <= CASIMIR_RTOL


def test_strang_energy_error_is_bounded_without_drift():
    traj = jaxsplit.integrate(jaxsplit.splitting(BODY, "strang"), M0, 0.1, 100_000, save_every=10)
    error = np.abs(np.asarray(BODY.hamiltonian(traj.x)) - float(BODY.hamiltonian(M0)))
    t = np.asarray(traj.t)
    assert error.max() <= STRANG_ENERGY_BOUND
    assert abs(np.polyfit(t, error, 1)[0] * t[-1]) <= DRIFT_TOL * error.max()
    tenth = len(error) // 10
    assert error[-tenth:].max() <= (1 + DRIFT_TOL) * error[:tenth].max()


def test_lie_trotter_does_not_conserve_energy():
    """Remark 4.1 of the paper, and a must-fail case for the energy check above."""
    traj = jaxsplit.integrate(jaxsplit.splitting(BODY, "lie-trotter"), M0, 0.1, 1000, save_every=10)
    error = np.abs(np.asarray(BODY.hamiltonian(traj.x)) - float(BODY.hamiltonian(M0)))
    assert error.max() > 100 * CASIMIR_RTOL
