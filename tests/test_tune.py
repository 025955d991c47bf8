"""tune_scheme: exact order conditions, measured order, and the held-out comparison (acceptance 4)."""

import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError
from jaxsplit.explore._tune import order4_parameters

CONDITION_TOL = 1e-14  # Σγ − 1 and Σγ³ for any free parameters
ORDER_TOL = 0.25  # measured order of the learned method vs 4
WIN_FACTOR = 0.8  # acceptance 4: learned geometric-mean error <= 0.8 x best published, equal cost
T_END = 10.0
PUBLISHED_STEPS = 40  # 5-stage tables: 200 Strang stages over T_END
TUNED_STEPS = 28  # 7 stages: 196 Strang stages, no more work than the tables


def test_free_parameters_satisfy_the_order_conditions_exactly():
    rng = np.random.default_rng(0)
    for k in (1, 2, 4):
        for z in rng.normal(0, 2, (20, k)):
            g = jaxsplit.order4_coefficients(z)
            assert len(g) == 2 * k + 3 and np.allclose(g, g[::-1], rtol=0, atol=0)
            scale = np.sum(np.abs(g) ** 3)
            assert abs(np.sum(g) - 1) < CONDITION_TOL * max(1, np.abs(g).sum())
            assert abs(np.sum(g**3)) < CONDITION_TOL * scale


@pytest.mark.parametrize("name", ["suzuki-5", "mclachlan-ss5"])
def test_published_five_stage_tables_are_in_the_family(name):
    g = np.array(jaxsplit.schemes[name].coefficients)
    np.testing.assert_allclose(jaxsplit.order4_coefficients(order4_parameters(g)), g, rtol=0, atol=1e-15)


# The two tests of the tuned scheme run on one xdist worker: the module fixture tunes once, not once per worker.
SHARED_TUNING = pytest.mark.xdist_group("tuned-scheme")


@pytest.fixture(scope="module")
def tuned():
    inertias, states = jaxsplit.random_bodies(24, seed=1)
    # converged at 100 iterations: held-out ratio learned/best 0.692 at 100 and at 300 (limit 0.8)
    return jaxsplit.tune_scheme(inertias, states, stages=7, t_end=T_END, n_steps=TUNED_STEPS,
                                iterations=100, learning_rate=0.05)


@SHARED_TUNING
def test_learned_method_has_order_four(tuned):
    sc = jaxsplit.STANDARD_CASE
    counts = np.array([20, 28, 40, 56, 80])
    cases = {"m0": np.tile(sc.m0, (len(counts), 1)), "inertia": np.tile(sc.inertia, (len(counts), 1)),
             "h": sc.t_end / counts}
    out = jaxsplit.sweep(tuned.scheme, cases, t_end=sc.t_end, allow_nonphysical=True)
    assert abs(jaxsplit.fit_order(out["h"], out["error"]).order - 4) < ORDER_TOL
    assert tuned.loss < 0 and np.all(np.isfinite(tuned.history))


@SHARED_TUNING
def test_learned_beats_best_published_of_equal_cost_on_held_out_bodies(tuned):
    inertias, states = jaxsplit.random_bodies(64, seed=99)

    def geo_mean(scheme, n_steps):
        cases = {"m0": states, "inertia": inertias, "h": np.full(len(states), T_END / n_steps)}
        err = jaxsplit.sweep(scheme, cases, t_end=T_END)["error"]
        return float(np.exp(np.mean(np.log(err))))

    learned = geo_mean(tuned.scheme, TUNED_STEPS)
    best = min(geo_mean(name, PUBLISHED_STEPS) for name in ("suzuki-5", "mclachlan-ss5"))
    assert learned < WIN_FACTOR * best, (learned, best)


def test_bad_arguments():
    inertias, states = jaxsplit.random_bodies(2)
    with pytest.raises(InputError, match="stages"):
        jaxsplit.tune_scheme(inertias, states, stages=4)
    with pytest.raises(InputError, match="auto"):
        jaxsplit.tune_scheme(inertias, states, split="casimir", shift="auto")
    with pytest.raises(InputError, match="states"):
        jaxsplit.tune_scheme(inertias, states[:1])
    with pytest.raises(InputError, match="start"):
        jaxsplit.tune_scheme(inertias, states, stages=7, start=[1.0])
