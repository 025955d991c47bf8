"""Fitting a hidden heavy-top centre of mass from noisy (t, m, Γ) data (issue 9, acceptance 4).

Only weight·χ enters the equations of the heavy top, so (t, m, Γ) determines that product
and, given the weight, χ: ``jaxsplit.fit`` on the family χ -> heavy_top(I, χ, weight) recovers
it to COM_TOL, and the Gauss–Newton Hessian JᵀJ of its residuals (χ and the initial state)
has no null direction. With the weight free too, JᵀJ has exactly one: d log(weight) = 1,
dχ = −χ (the must-fail of identifiability). No helper is needed: the gauge is the weight,
stated by fixing it.
"""

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.explore._fit import predict

COM_TOL = 0.01  # acceptance: χ recovered to 1 % (relative to |χ|; measured 4.5e-4 at NOISE, σ̂ ≈ 2e-4 per component)
NOISE = 1e-3  # standard deviation of the observation noise on every component of m and Γ
NULL_RATIO = 1e-10  # an eigenvalue of JᵀJ below this share of the largest is a null direction
DETERMINED_RATIO = 1e-6  # every eigenvalue above this share: the data fix every parameter (measured 1e-3)
NULL_ALIGNMENT = 1 - 1e-8  # |cos| between the null eigenvector and (−χ, 1)

INERTIA = jnp.array([2.0, 1.0, 2.0 / 3.0])
CHI = jnp.array([0.1, -0.2, 0.5])
WEIGHT = 1.3
X0 = (jnp.array([0.4, -0.3, 0.8]), jnp.array([0.1, 0.9, -0.4]) / np.linalg.norm([0.1, 0.9, -0.4]))
T = np.linspace(0.0, 6.0, 31)


def known_weight(params):
    return jaxsplit.heavy_top(INERTIA, params["com"], WEIGHT, allow_nonphysical=True)


def free_weight(params):
    return jaxsplit.heavy_top(INERTIA, params["com"], jnp.exp(params["log_weight"]), allow_nonphysical=True)


@pytest.fixture(scope="module")
def observed():
    return jaxsplit.simulate(known_weight, {"com": CHI}, X0, T, noise=NOISE, seed=3)


def test_fit_recovers_the_hidden_center_of_mass(observed):
    result = jaxsplit.fit(known_weight, T, observed, {"com": jnp.zeros(3)}, scheme="strang", max_step=0.1,
                          adam_steps=0)
    error = np.linalg.norm(result.params["com"] - np.asarray(CHI)) / np.linalg.norm(CHI)
    assert error <= COM_TOL, (result.params, error)
    eigenvalues = result.hessian_eigenvalues
    assert eigenvalues[0] >= DETERMINED_RATIO * eigenvalues[-1], eigenvalues


def test_with_a_free_weight_the_data_leave_one_null_direction():
    """JᵀJ of the residuals at the truth, as ``fit`` computes it, over (χ, log weight)."""
    theta = {"com": CHI, "log_weight": jnp.log(WEIGHT)}
    flat, unravel = jax.flatten_util.ravel_pytree(theta)
    dts = jnp.asarray(np.diff(T))

    def states(f):
        x = predict(free_weight, unravel(f), X0, dts, scheme=jaxsplit.schemes["strang"], n_sub=2)
        return jnp.concatenate([a.reshape(-1) for a in jax.tree_util.tree_leaves(x)])

    jac = jax.jit(jax.jacfwd(states))(flat)
    eigenvalues, vectors = np.linalg.eigh(np.asarray(jac.T @ jac))
    assert eigenvalues[0] <= NULL_RATIO * eigenvalues[-1], eigenvalues
    assert eigenvalues[1] >= DETERMINED_RATIO * eigenvalues[-1], eigenvalues  # one null direction only
    expected = np.asarray(jax.flatten_util.ravel_pytree({"com": -CHI, "log_weight": jnp.array(1.0)})[0])
    cosine = abs(vectors[:, 0] @ expected) / np.linalg.norm(expected)
    assert cosine >= NULL_ALIGNMENT, (vectors[:, 0], expected)
