"""The so(3) toolkit: the rotation convention, batching over leading axes, rotations about
arbitrary vectors, quaternions, and rotation flows that turn declared parts of a state."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import jaxsplit
from jaxsplit import InputError
from jaxsplit.systems import so3

ROUNDOFF = 1e-14
ODE_TOL = 1e-11  # DOP853 at rtol = atol = 1e-13 over t = 3

X = np.array([0.3, -0.5, 0.8])
N = np.array([0.2, -0.6, 0.7]) / np.linalg.norm([0.2, -0.6, 0.7])


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_convention_is_exp_of_minus_theta_hat(axis):
    """rotate(x, k, θ) = exp(−θ hat(e_k)) x = the paper's M, N, P: −θ about e_k."""
    theta = 0.7
    expected = expm(-theta * np.asarray(jaxsplit.hat(jnp.eye(3)[axis]))) @ X
    np.testing.assert_allclose(jaxsplit.rotate(jnp.asarray(X), axis, theta), expected, atol=ROUNDOFF)
    np.testing.assert_allclose(jaxsplit.rotation_matrix(axis, theta) @ X, expected, atol=ROUNDOFF)
    np.testing.assert_allclose(jaxsplit.rotate_about(jnp.asarray(X), jnp.eye(3)[axis], theta), expected,
                               atol=ROUNDOFF)


def test_rotation_about_any_vector_is_rodrigues():
    theta = -1.3
    expected = expm(-theta * np.asarray(jaxsplit.hat(jnp.asarray(N)))) @ X
    np.testing.assert_allclose(jaxsplit.rotate_about(jnp.asarray(X), jnp.asarray(3.0 * N), theta), expected,
                               atol=ROUNDOFF)
    np.testing.assert_allclose(jaxsplit.rotation_matrix_about(jnp.asarray(N), theta) @ X, expected, atol=ROUNDOFF)


def test_rotations_broadcast_over_leading_axes():
    xs = jax.random.normal(jax.random.PRNGKey(0), (4, 5, 3))
    angles = jax.random.normal(jax.random.PRNGKey(1), (4, 5))
    for axis in range(3):
        batched = jaxsplit.rotate(xs, axis, angles)
        for i in range(4):
            for j in range(5):
                np.testing.assert_allclose(batched[i, j], jaxsplit.rotate(xs[i, j], axis, angles[i, j]),
                                           atol=ROUNDOFF)
    flow = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True).split("axes")[1]
    batched = flow(xs, 0.3)
    np.testing.assert_allclose(batched[2, 3], flow(xs[2, 3], 0.3), atol=ROUNDOFF)


def test_vector_rotation_is_the_exact_group_flow_of_its_piece():
    c = 1.7
    flow = jaxsplit.VectorRotation(jnp.asarray(N), c)
    field = lambda t, m: np.cross(m, c * (N @ m) * N)  # ṁ = m × ∇(½ c ⟨n, m⟩²)
    ref = solve_ivp(field, (0, 3.0), X, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(flow(jnp.asarray(X), 3.0), ref, atol=ODE_TOL)
    np.testing.assert_allclose(flow(flow(jnp.asarray(X), 1.1), 1.9), flow(jnp.asarray(X), 3.0), atol=ROUNDOFF)


def test_quaternions():
    q = jnp.array([0.8, 0.1, -0.3, 0.5])
    q = q / jnp.linalg.norm(q)
    r = jnp.array([np.cos(0.35), *(np.sin(0.35) * N)])
    product = jaxsplit.quaternion_multiply(q, r)
    np.testing.assert_allclose(jaxsplit.quaternion_to_matrix(product),
                               jaxsplit.quaternion_to_matrix(q) @ jaxsplit.quaternion_to_matrix(r), atol=ROUNDOFF)
    # r turns by +0.7 about n: the transpose of exp(−0.7 hat(n))
    np.testing.assert_allclose(jaxsplit.quaternion_to_matrix(r), jaxsplit.rotation_matrix_about(N, 0.7).T,
                               atol=ROUNDOFF)


@pytest.mark.parametrize("flow_kind", ["axis", "vector"])
def test_declared_parts_turn_with_m(flow_kind):
    """(m, Γ, Q, q, fixed): Γ turns like m, Q ← Q Rᵀ (so Q m is kept), q ← q ⊗ r, fixed kept."""
    c = 0.9
    flow = (jaxsplit.AxisRotation(2, c, ("momentum", "vector", "attitude", "quaternion", "fixed"))
            if flow_kind == "axis" else
            jaxsplit.VectorRotation(N, c, ("momentum", "vector", "attitude", "quaternion", "fixed")))
    m, gamma = jnp.asarray(X), jnp.array([0.0, 0.6, 0.8])
    q = jnp.array([0.8, 0.1, -0.3, 0.5]) / jnp.linalg.norm(jnp.array([0.8, 0.1, -0.3, 0.5]))
    big_q = jaxsplit.quaternion_to_matrix(q)
    extra = jnp.array([1.0, 2.0])
    out = flow((m, gamma, big_q, q, extra), 1.3)
    direction = jnp.eye(3)[2] if flow_kind == "axis" else jnp.asarray(N)
    angle = c * (direction @ m) * 1.3
    rot = jaxsplit.rotation_matrix_about(direction, angle)
    np.testing.assert_allclose(out[0], rot @ m, atol=ROUNDOFF)
    np.testing.assert_allclose(out[1], rot @ gamma, atol=ROUNDOFF)
    np.testing.assert_allclose(out[2], big_q @ rot.T, atol=ROUNDOFF)
    np.testing.assert_allclose(jaxsplit.quaternion_to_matrix(out[3]), big_q @ rot.T, atol=ROUNDOFF)
    np.testing.assert_allclose(out[2] @ out[0], big_q @ m, atol=ROUNDOFF)  # spatial momentum kept
    assert abs(float(jnp.linalg.norm(out[3])) - 1) < ROUNDOFF
    assert out[4] is extra


def test_bad_parts_and_axes():
    with pytest.raises(InputError, match="exactly one 'momentum'"):
        jaxsplit.AxisRotation(0, 1.0, ("vector", "vector"))
    with pytest.raises(InputError, match="parts"):
        jaxsplit.AxisRotation(0, 1.0, ("momentum", "velocity"))
    with pytest.raises(InputError, match="axis must be 0, 1 or 2"):
        jaxsplit.AxisRotation(3, 1.0)
    with pytest.raises(InputError, match="axis must be 0, 1 or 2"):
        jaxsplit.rotate(jnp.ones(3), 3, 0.1)
    flow = jaxsplit.AxisRotation(0, 1.0, ("momentum", "attitude"))
    with pytest.raises(InputError, match=r"the attitude part must have shape \(\.\.\., 3, 3\)"):
        flow((jnp.ones(3), jnp.ones(3)), 0.1)


def test_so3_namespace_is_the_toolkit():
    assert so3.rotate is jaxsplit.rotate and so3.hat is jaxsplit.hat
    assert set(so3.PARTS) == {"momentum", "vector", "attitude", "quaternion", "fixed"}
