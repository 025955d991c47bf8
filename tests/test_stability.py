"""stability_map: eigenvalues of DΦ at the relative equilibria, against independent checks."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError

DET_TOL = 1e-12  # tangent block of a Poisson map is area preserving
EIG_TOL = 1e-12  # closed-form 2x2 eigenvalues vs numpy eigvals of the full jacobian (relative)
SMALL_H_RADIUS_RTOL = 1e-3  # discrete vs exact growth factor at the middle axis, h = 0.05
ORDER_TOL = 0.15  # Strang's local angle error is O(h^3)

BODIES = np.array([[2.0, 1.0, 2 / 3], [1.0, 1.5, 2.0]])  # the first is the (non-physical) standard body
HS = np.array([0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])


@pytest.fixture(scope="module")
def strang_map():
    return jaxsplit.stability_map("strang", HS, BODIES, allow_nonphysical=True)


def test_structure(strang_map):
    r = strang_map
    assert r["eigenvalues"].shape == (len(HS), len(BODIES), 3, 3)
    assert np.max(np.abs(r["det"] - 1)) < DET_TOL
    assert np.max(r["fixed_point_error"]) == 0.0
    assert np.max(np.abs(r["eigenvalues"][..., 0] - 1)) < DET_TOL
    # exact flow: only the axis with the middle moment is unstable
    for b, inertia in enumerate(BODIES):
        middle = int(np.argsort(inertia)[1])
        assert np.array_equal(r["exact_stable"][0, b], [k != middle for k in range(3)])


def test_eigenvalues_match_numpy_on_the_full_jacobian(strang_map):
    @jax.jit  # one compiled Jacobian for every (h, body, axis): the body's inertia is traced
    def jacobian(inertia, x, h):
        return jax.jacfwd(jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang"))(x, h)

    for hi in (1, 6):
        for b in range(len(BODIES)):
            for axis in range(3):
                e = jnp.eye(3)[axis]
                jac = np.asarray(jacobian(jnp.asarray(BODIES[b]), e, HS[hi]))
                ref = np.sort_complex(np.linalg.eigvals(jac))
                got = np.sort_complex(strang_map["eigenvalues"][hi, b, axis])
                assert np.max(np.abs(ref - got)) < EIG_TOL * max(1.0, np.abs(got).max())


def test_small_steps_follow_the_exact_linearisation(strang_map):
    r = strang_map
    assert np.all(r["stable"][0] == r["exact_stable"][0])
    unstable = ~r["exact_stable"][0]
    np.testing.assert_allclose(r["spectral_radius"][0][unstable], r["exact_spectral_radius"][0][unstable],
                               rtol=SMALL_H_RADIUS_RTOL)
    # rotation angle per step converges with local order 3 (Strang): h = HS[0] = 0.05 against 0.025
    # (the halved grid has the shape of the map above: its compiled kernel is reused)
    fine = jaxsplit.stability_map("strang", HS / 2, BODIES, allow_nonphysical=True)
    err = [np.abs(m["angle"][0] - m["exact_angle"][0]) for m in (r, fine)]
    stable = fine["exact_stable"][0]
    slope = np.log2(err[0][stable] / err[1][stable])
    assert np.all(np.abs(slope - 3) < ORDER_TOL)


def test_large_steps_lose_stability(strang_map):
    r = strang_map
    lost = r["first_unstable_h"]
    assert np.any(np.isfinite(lost))  # Strang stops being stable somewhere on this grid
    for b in range(len(BODIES)):
        for axis in range(3):
            h = lost[b, axis]
            if np.isfinite(h):
                idx = int(np.nonzero(HS == h)[0][0])
                assert r["exact_stable"][idx, b, axis] and not r["stable"][idx, b, axis]
                assert np.all(r["stable"][:idx, b, axis] | ~r["exact_stable"][:idx, b, axis])


def test_casimir_split_grouping():
    r = jaxsplit.stability_map("strang", [0.1], BODIES, split="casimir", allow_nonphysical=True)
    assert np.max(np.abs(r["det"] - 1)) < DET_TOL
    assert np.array_equal(r["stable"], r["exact_stable"])


@pytest.mark.parametrize("hs, inertias, match", [
    ([-0.1], BODIES, "step_sizes"),
    ([0.1], [[1.0, -1.0, 2.0]], "inertias"),
    ([0.1], [[1.0, 2.0]], "inertias"),
])
def test_bad_input(hs, inertias, match):
    with pytest.raises(InputError, match=match):
        jaxsplit.stability_map("strang", hs, inertias)
