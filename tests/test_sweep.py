"""sweep / sweep_cases: per-case metrics against independent computations, chunking, memory."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError
from jaxsplit.explore._batch import any_body, resolved_groups
from jaxsplit.explore._sweep import _case_kernel

REFERENCE_TOL = 1e-13  # reference_solution vs the 30-digit value of the standard case
HALF_STEP_TOL = 1e-12  # |reference - the half-step-count run|, a bound on the reference error
MATCH_TOL = 1e-12  # sweep's final state vs jaxsplit.integrate of the same case
CASIMIR_TOL = 1e-13  # every splitting keeps |m| to round-off
POISSON_TOL = 1e-13  # defect of an exact Poisson map
ORDER_TOL = 0.1  # Strang's observed order vs 2
CHUNK_TOL = 1e-15  # chunk size must not change any per-case number
MEMORY_PER_CASE = 2 * 1024  # bytes of XLA temporaries per case (measured ~0.7 KiB)

SC = jaxsplit.STANDARD_CASE


def _standard_cases(step_sizes):
    cases = jaxsplit.sweep_cases(states=[SC.m0], ratios=[np.array(SC.inertia[1:]) / SC.inertia[0]],
                                 step_sizes=step_sizes, physical_only=False)  # (2, 1, 2/3): non-physical
    cases["inertia"] = cases["inertia"] * SC.inertia[0]
    return cases


def test_grid_cases_layout():
    cases = jaxsplit.sweep_cases(states=5, ratios=[(1.0, 0.5), (2.0, 1.5)], step_sizes=[0.1, 0.2, 0.3])
    assert cases["m0"].shape == (30, 3) and cases["h"].shape == (30,)
    np.testing.assert_allclose(np.linalg.norm(cases["m0"], axis=1), 1, rtol=0, atol=1e-15)
    grid = cases["h"].reshape(2, 3, 5)
    assert np.all(grid == np.array([0.1, 0.2, 0.3])[None, :, None])
    assert np.all(cases["inertia"].reshape(2, 3, 5, 3)[1, :, :, 1] == 2.0)
    assert np.all(cases["state_index"].reshape(2, 3, 5) == np.arange(5))


def test_random_cases_are_physical_unit_and_reproducible():
    a = jaxsplit.sweep_cases(sampling="random", n_samples=500, seed=3, ratio_range=(0.2, 5.0))
    b = jaxsplit.sweep_cases(sampling="random", n_samples=500, seed=3, ratio_range=(0.2, 5.0))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    np.testing.assert_allclose(np.linalg.norm(a["m0"], axis=1), 1, rtol=0, atol=1e-15)
    assert jaxsplit.RigidBody(a["inertia"]).is_physical()
    assert np.all((a["h"] >= 0.01) & (a["h"] <= 0.5))


def test_standard_case_against_integrate_and_reference():
    hs = [0.1, 0.05, 0.025]
    out = jaxsplit.sweep("strang", _standard_cases(hs), t_end=SC.t_end, allow_nonphysical=True)
    assert np.max(np.abs(out["reference"] - np.array(SC.reference))) < REFERENCE_TOL
    assert np.all(out["reference_accuracy"] < HALF_STEP_TOL)
    body = jaxsplit.RigidBody(jnp.asarray(SC.inertia), allow_nonphysical=True)
    for h, n, m in zip(out["h"], out["n_steps"], out["m_final"]):
        direct = jaxsplit.integrate(jaxsplit.splitting(body, "strang"), jnp.asarray(SC.m0), h, int(n)).final
        assert np.max(np.abs(np.asarray(direct) - m)) < MATCH_TOL
        energy = body.hamiltonian(direct)
        assert out["energy_error"][list(out["h"]).index(h)] >= abs(energy / body.hamiltonian(jnp.asarray(SC.m0)) - 1)
    assert np.all(out["casimir_error"] < CASIMIR_TOL)
    assert np.all(out["poisson_defect"] < POISSON_TOL)
    order = np.polyfit(np.log(out["h"]), np.log(out["error"]), 1)[0]
    assert abs(order - 2) < ORDER_TOL


def test_poisson_defect_is_roundoff_even_at_large_steps():
    cases = jaxsplit.sweep_cases(states=4, ratios=[(0.7, 1.4)], step_sizes=[0.5, 2.0])
    out = jaxsplit.sweep("mclachlan-ss5", cases, t_end=4.0)
    assert np.all(out["poisson_defect"] < POISSON_TOL)


def test_chunking_does_not_change_results():
    cases = jaxsplit.sweep_cases(sampling="random", n_samples=37, seed=1, h_range=(0.05, 0.3))
    big = jaxsplit.sweep("suzuki-5", cases, t_end=3.0, split="casimir", shift=1, chunk_size=1024)
    small = jaxsplit.sweep("suzuki-5", cases, t_end=3.0, split="casimir", shift=1, chunk_size=8)
    for key in big:
        assert np.max(np.abs(np.asarray(big[key], float) - np.asarray(small[key], float))) <= CHUNK_TOL, key
    k = 11
    body = jaxsplit.RigidBody(jnp.asarray(cases["inertia"][k]))
    direct = jaxsplit.integrate(jaxsplit.splitting(body, "suzuki-5", "casimir", shift=1),
                                jnp.asarray(cases["m0"][k]), big["h"][k], int(big["n_steps"][k])).final
    assert np.max(np.abs(np.asarray(direct) - big["m_final"][k])) < MATCH_TOL


def test_auto_shift_axis_is_the_middle_inverse_moment():
    inertia = np.array([[2.0, 1.0, 2 / 3], [1.0, 3.0, 2.0], [1.0, 0.5, 0.8]])
    groups = resolved_groups(any_body, inertia, "casimir", {"shift": "auto"})  # (2, 1, 2/3) included
    assert sorted(i for *_, idx in groups for i in idx) == [0, 1, 2]
    for name, options, idx in groups:
        for row in inertia[idx]:
            assert name == "casimir" and options["shift"] == int(np.argsort(1 / row)[1])
            assert options["shift"] == any_body(row).shift_axis("auto")


def test_dtype_follows_the_cases():
    cases = jaxsplit.sweep_cases(states=3, step_sizes=[0.2], dtype=np.float32)
    out = jaxsplit.sweep("strang", cases, t_end=1.0)
    assert out["m_final"].dtype == np.float32 and out["energy_error"].dtype == np.float32


def test_device_memory_is_bounded_per_chunk():
    fn = jax.jit(_case_kernel(jaxsplit.RigidBody, jaxsplit.schemes["kahan-li-8"], "axes", ()))
    sizes = {}
    for b in (16, 128):
        args = (jnp.ones((b, 3)), jnp.ones((b, 3)), jnp.ones(b), jnp.ones(b, dtype=jnp.int64))
        sizes[b] = fn.lower(*args).compile().memory_analysis().temp_size_in_bytes
    assert sizes[128] / 128 < MEMORY_PER_CASE and sizes[16] / 16 < MEMORY_PER_CASE
    # the step count is a traced input: one program, whatever n is, so memory cannot grow with it


@pytest.mark.parametrize("kwargs, match", [
    ({"t_end": -1.0}, "t_end"),
    ({"t_end": 1.0, "chunk_size": 0}, "chunk_size"),
    ({"t_end": 1.0, "split": "diagonal"}, "split"),
    ({"t_end": 1.0, "shift": 3, "split": "casimir"}, "shift"),
])
def test_bad_arguments(kwargs, match):
    cases = jaxsplit.sweep_cases(states=2)
    with pytest.raises(InputError, match=match):
        jaxsplit.sweep("strang", cases, **kwargs)


def test_bad_cases():
    with pytest.raises(InputError, match="cases"):
        jaxsplit.sweep("strang", {"m0": np.ones((2, 3))}, t_end=1.0)
    cases = jaxsplit.sweep_cases(states=2)
    cases["inertia"] = -cases["inertia"]
    with pytest.raises(InputError, match="inertia"):
        jaxsplit.sweep("strang", cases, t_end=1.0)
    with pytest.raises(InputError, match="sampling"):
        jaxsplit.sweep_cases(sampling="sobol")
    with pytest.raises(InputError, match="ratios"):
        jaxsplit.sweep_cases(ratios=[(1.0, -2.0)])
