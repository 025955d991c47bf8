"""The rigid body: vector field from Π∇H (independently, by jax.grad), validation, PyTree."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxsplit
from jaxsplit import InputError, RigidBody

ROUNDOFF = 1e-14
ODE_TOL = 1e-12


def test_vector_field_is_poisson_matrix_times_gradient():
    body = RigidBody([2.0, 1.0, 2.0 / 3.0], allow_nonphysical=True)
    for m in jax.random.normal(jax.random.PRNGKey(0), (5, 3)):
        expected = body.poisson_matrix(m) @ jax.grad(body.hamiltonian)(m)
        np.testing.assert_allclose(body.vector_field(m), expected, atol=ROUNDOFF)
        assert abs(jax.grad(body.casimir)(m) @ body.vector_field(m)) < ROUNDOFF


@pytest.mark.parametrize("inertia, message", [
    ([1.0, -1.0, 2.0], "positive"), ([1.0, 0.0, 2.0], "positive"), ([1.0, np.nan, 2.0], "finite"),
    ([1.0, np.inf, 2.0], "finite"), ([1.0, 2.0], "3 components"), ("abc", "numeric|real"),
])
def test_bad_inertia_is_refused_with_the_value_named(inertia, message):
    with pytest.raises(InputError, match=message):
        RigidBody(inertia)


def test_integer_inertia_is_promoted_and_physicality_checked():
    body = RigidBody([2, 2, 1])
    assert jnp.issubdtype(body.inertia.dtype, jnp.floating)
    assert body.is_physical() and not RigidBody([1.0, 1.0, 3.0], allow_nonphysical=True).is_physical()


def test_body_is_a_pytree_for_vmap_and_grad():
    inertias = jnp.array([[2.0, 1.0, 0.5], [3.0, 2.0, 1.5]])
    m = jnp.array([0.3, 0.4, 0.5])
    energies = jax.vmap(lambda i: RigidBody(i).hamiltonian(m))(inertias)
    np.testing.assert_allclose(energies, 0.5 * (m**2 / inertias).sum(1), rtol=ROUNDOFF)
    grad = jax.grad(lambda i: RigidBody(i).hamiltonian(m))(inertias[0])
    np.testing.assert_allclose(grad, -0.5 * m**2 / inertias[0] ** 2, rtol=ROUNDOFF)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_axis_rotation_is_the_exact_flow_of_its_piece(axis):
    """Each of M, N, P against a tight DOP853 integration of ṁ = m × ∇H_axis."""
    body = RigidBody([2.0, 1.0, 2.0 / 3.0], allow_nonphysical=True)
    m0 = np.array([0.3, -0.5, 0.8])
    field = lambda t, m: np.cross(m, np.eye(3)[axis] * m[axis] / body.inertia[axis])
    ref = solve_ivp(field, (0, 3.0), m0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(body.split("axes")[axis](jnp.asarray(m0), 3.0), ref, atol=ODE_TOL)


def test_symmetric_solution_matches_an_independent_integration():
    body = RigidBody(jnp.asarray(jaxsplit.PAPER_BODY))
    m0 = np.asarray(jaxsplit.PAPER_M0)
    ts = np.linspace(0, 20, 9)
    ref = solve_ivp(lambda t, m: np.asarray(body.vector_field(jnp.asarray(m))), (0, 20), m0,
                    method="DOP853", t_eval=ts, rtol=1e-13, atol=1e-13).y.T
    np.testing.assert_allclose(jaxsplit.symmetric_solution(body, m0, ts), ref, atol=ODE_TOL)
    with pytest.raises(InputError, match="not symmetric"):
        jaxsplit.symmetric_solution(RigidBody([1.0, 2.0, 3.0]), m0, 1.0)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rotate_applies_the_papers_matrix(axis):
    """rotate(m, k, θ) = M m, N m or P m, and the matrices are proper rotations."""
    m = jnp.array([0.3, -0.5, 0.8])
    matrix = jaxsplit.rotation_matrix(axis, 0.7)
    np.testing.assert_allclose(jaxsplit.rotate(m, axis, 0.7), matrix @ m, atol=ROUNDOFF)
    np.testing.assert_allclose(matrix @ matrix.T, np.eye(3), atol=ROUNDOFF)
    assert abs(np.linalg.det(matrix) - 1) < ROUNDOFF
