"""``auto_splitting``: the scheme, split and step for a tolerance, checked against exact and
independent references (the choice is a model's prediction; the error is measured here)."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError

SAFETY = 3.0  # measured error at t_end <= SAFETY · tol
PILOT_ROUND_OFF = 1e-13  # pilot error against integrate's, 20 and 40 steps (measured 7e-16, 5.5e-16)
COARSER = 3  # the chosen scheme at COARSER × the chosen step misses tol: the choice is not wasteful

CASE = jaxsplit.STANDARD_CASE
BODY = jaxsplit.RigidBody(jnp.asarray(CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(CASE.m0)
REFERENCE = jnp.asarray(CASE.reference)  # 30 digits at t = 10


def _error(choice, x0, h, n, reference):
    """The chosen step, rolled (the same map; its word as arrays compiles in a fraction of the time)."""
    return float(jnp.max(jnp.abs(jaxsplit.integrate(jaxsplit.roll(choice.step), x0, h, n).final - reference)))


@pytest.mark.parametrize("tol", [1e-6, 1e-10])
def test_the_choice_reaches_the_tolerance_on_the_standard_case(tol):
    choice = jaxsplit.auto_splitting(BODY, M0, tol=tol, t_end=CASE.t_end)
    assert choice.n_steps * choice.h == pytest.approx(CASE.t_end)
    assert _error(choice, M0, choice.h, choice.n_steps, REFERENCE) <= SAFETY * tol
    coarse = max(1, choice.n_steps // COARSER)
    assert _error(choice, M0, CASE.t_end / coarse, coarse, REFERENCE) > tol
    # the winner is the cheapest of the modelled candidates, and a tighter tolerance costs more
    assert choice.cost == min(c["cost"] for c in choice.candidates)
    if tol < 1e-6:
        assert choice.cost > jaxsplit.auto_splitting(BODY, M0, tol=1e-6, t_end=CASE.t_end).cost


def test_a_long_horizon_batch_on_a_near_symmetric_body():
    """T = 100, four states of I = (1, 1.01, 0.5): the worst state counts; reference by
    Kahan–Li 10 at sub-step angles <= 0.005 (its own error ~1e-13 here)."""
    body = jaxsplit.RigidBody(jnp.asarray([1.0, 1.01, 0.5]))
    states = jnp.asarray(jaxsplit.random_bodies(4, seed=5)[1])
    choice = jaxsplit.auto_splitting(body, states, tol=1e-8, t_end=100.0)
    fine = jaxsplit.roll(jaxsplit.splitting(body, "kahan-li-10", "casimir", shift=0))
    reference = jaxsplit.integrate(fine, states, 100.0 / 20_000, 20_000).final
    assert _error(choice, states, choice.h, choice.n_steps, reference) <= SAFETY * 1e-8


def test_a_processed_candidate_is_piloted_as_integrate_runs_it():
    """The pilot runs a processed scheme as P⁻¹ ∘ K^n ∘ P (its kernel rolled, P and P⁻¹ once):
    the errors it reads are those of ``integrate`` with the step itself."""
    from jaxsplit.systems import _auto

    step = jaxsplit.splitting(BODY, "blanes-casas-murua-8", "casimir")
    counts = [20, 40]
    _, errors = _auto._pilot_errors(step, M0, CASE.t_end, counts, REFERENCE)
    direct = [_error(jaxsplit.AutoSplitting(step, *[None] * 8), M0, CASE.t_end / n, n, REFERENCE) for n in counts]
    assert np.max(np.abs(errors - np.asarray(direct))) <= PILOT_ROUND_OFF, (errors, direct)


def test_the_pilot_ladder_stops_in_the_round_off_floor():
    """The ladder stops after its first error below ``stop``: the same errors up to there, the
    dearer rest (round-off only) not run."""
    from jaxsplit.systems import _auto

    step = jaxsplit.splitting(BODY, "kahan-li-8", "casimir")
    counts = [10, 14, 20, 28, 40, 56, 80]
    hs, full = _auto._pilot_errors(step, M0, CASE.t_end, counts, REFERENCE)
    stop = 1e-10
    assert np.sum(full < stop) >= 2  # the ladder reaches the floor before its end
    hs_stopped, stopped = _auto._pilot_errors(step, M0, CASE.t_end, counts, REFERENCE, stop)
    k = len(stopped)
    assert np.array_equal(stopped, full[:k]) and np.array_equal(hs_stopped, hs[:k])
    assert stopped[-1] < stop <= np.min(stopped[:-1]) and k < len(counts)


def test_round_off_at_the_smallest_pilot_steps_is_not_read_as_truncation_error():
    """A high-order scheme reaches the pilot's round-off floor (~1e-12) well inside the ladder;
    those points would imply an error constant orders of magnitude too large."""
    from jaxsplit.systems import _auto

    step = jaxsplit.splitting(BODY, "kahan-li-8", "casimir")
    hs, constant, t = 1.5 * 2.0 ** -np.arange(0, 7.5, 0.5), 2e-8, 20.0
    errors = np.maximum(constant * hs**8 * t, 1e-12)  # truncation error, then the round-off floor
    assert np.max(errors / (hs**8 * t)) > 1e3 * constant  # the trap is in the data
    row = _auto._candidate(step, step.scheme, "casimir", {}, hs, errors, t, 1e-8, 1000.0, M0, (2.2e-13, 1e-3))
    assert row["error_constant"] == pytest.approx(constant, rel=1e-9)


def test_the_cost_is_the_runs_sub_flows():
    """Every rotation runs one kernel whatever its angle, so a candidate costs the sub-flows its run
    evaluates: n steps of the merged word and a processor's P and P⁻¹ once."""
    from jaxsplit.systems import _auto

    hs, t = 1.5 * 2.0 ** -np.arange(0, 7.5, 0.5), 20.0
    for scheme in ("kahan-li-8", "strang", "blanes-casas-murua-8"):
        step = jaxsplit.splitting(BODY, scheme, "casimir")
        p = step.scheme.order
        row = _auto._candidate(step, step.scheme, "casimir", {}, hs, 1e-3 * hs**p * t, t, 1e-4, 100.0, M0,
                               (2.2e-13, 1e-3))
        head, body, tail = step._sequences()
        assert row["cost"] == row["n_steps"] * step.flows_per_step + len(head) + len(tail)
        assert len(body) == step.flows_per_step


def test_bad_requests_are_one_line_errors():
    with pytest.raises(InputError, match="tol must be a positive number"):
        jaxsplit.auto_splitting(BODY, M0, tol=0.0, t_end=10.0)
    with pytest.raises(InputError, match="t_end must be a positive number"):
        jaxsplit.auto_splitting(BODY, M0, tol=1e-8, t_end=-1.0)
    with pytest.raises(InputError, match="below what float64 round-off allows"):
        jaxsplit.auto_splitting(BODY, M0, tol=1e-16, t_end=10.0)
    with pytest.raises(InputError, match="unknown scheme 'rk4'"):
        jaxsplit.auto_splitting(BODY, M0, tol=1e-8, t_end=10.0, candidates=("strang", "rk4"))
    with pytest.raises(InputError, match="not offered"):
        jaxsplit.auto_splitting(BODY, M0, tol=1e-8, t_end=10.0, splits=("symmetric",))
    with pytest.raises(InputError, match="needs a system"):
        jaxsplit.auto_splitting(np.ones(3), M0, tol=1e-8, t_end=10.0)
