"""sweep, stability_map and fit take any system family (issue 8): the user's system of
test_system_layer.py (a free body carrying a vector, state (m, v)) through each."""

import jax.numpy as jnp
import numpy as np
from test_system_layer import CarriedVector

import jaxsplit

CASIMIR_TOL = 1e-13
POISSON_TOL = 1e-13
ORDER_TOL = 0.15
RADIUS_RTOL = 1e-3  # discrete vs exact growth at the unstable axis, h = 0.02
FIT_RTOL = 0.01  # recovered moments (all three identifiable: v breaks the Casimir gauge)


def _cases(hs):
    rng = np.random.default_rng(3)
    m0 = rng.standard_normal((2, 3))
    v0 = rng.standard_normal((2, 3))
    inertia = np.array([[2.0, 1.0, 0.7], [1.0, 1.6, 2.2]])
    k = np.repeat(np.arange(2), len(hs))
    return {"x0": (m0[k], v0[k]), "params": inertia[k], "h": np.tile(hs, 2)}


def test_sweep_over_a_user_family():
    hs = np.array([0.2, 0.1, 0.05])
    out = jaxsplit.sweep("strang", _cases(hs), t_end=4.0, system=CarriedVector)
    assert {"energy_error", "|v|^2_error", "<m,v>_error", "x_final", "error"} <= set(out)
    assert np.all(out["|v|^2_error"] < CASIMIR_TOL) and np.all(out["<m,v>_error"] < CASIMIR_TOL)
    assert np.all(out["poisson_defect"] < POISSON_TOL)
    assert isinstance(out["x_final"], tuple) and out["x_final"][1].shape == (6, 3)
    assert np.all(out["reference_accuracy"] < 1e-10)
    for body in range(2):
        err = out["error"][3 * body:3 * body + 3]
        assert abs(np.polyfit(np.log(hs), np.log(err), 1)[0] - 2) < ORDER_TOL


def test_stability_map_over_a_user_family():
    def equilibria(system):  # steady rotation about e_i carrying v = e_i
        eye = jnp.eye(3)
        return (eye, eye)

    bodies = np.array([[2.0, 1.0, 0.7]])
    r = jaxsplit.stability_map("strang", [0.02, 3.0], bodies, system=CarriedVector, equilibria=equilibria)
    assert r["leaf_eigenvalues"].shape == (2, 1, 3, 4)
    assert np.max(np.abs(r["det"] - 1)) < 1e-12  # symplectic on the 4-dimensional leaf
    assert np.max(r["fixed_point_error"]) == 0.0
    assert np.array_equal(r["stable"][0], r["exact_stable"][0])
    middle = int(np.argsort(bodies[0])[1])  # steady rotation about the middle moment: unstable
    assert not r["exact_stable"][0, 0, middle]
    np.testing.assert_allclose(r["spectral_radius"][0, 0, middle], r["exact_spectral_radius"][0, 0, middle],
                               rtol=RADIUS_RTOL)
    assert "angle" not in r  # only for 2-dimensional leaves


def test_fit_recovers_a_user_systems_parameters():
    truth = np.array([1.3, 2.1, 2.9])
    x0 = (jnp.array([0.5, -0.4, 0.7]), jnp.array([0.2, 0.9, -0.3]))
    t = np.linspace(0.0, 12.0, 80)

    def family(log_inertia):
        return CarriedVector(jnp.exp(log_inertia))

    observed = jaxsplit.simulate(family, np.log(truth), x0, t, noise=1e-4, seed=5)
    # L-BFGS alone (no Adam warm-up): the same optimum, measured: largest relative error 1.1e-5,
    # 0.495 standard deviations, sigma 4% low, with or without the 50 Adam steps
    res = jaxsplit.fit(family, t, observed, np.log(np.array([1.0, 2.0, 3.0])), max_step=0.1, adam_steps=0)
    np.testing.assert_allclose(np.exp(res.params), truth, rtol=FIT_RTOL)
    assert np.all(np.abs(np.exp(res.params) - truth) < 5 * truth * res.params_std + 1e-12)
    assert abs(res.noise_sigma / 1e-4 - 1) < 0.3
    assert res.hessian_eigenvalues[0] > 1e-8 * res.hessian_eigenvalues[-1]  # nothing unidentifiable
