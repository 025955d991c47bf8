"""The composer and the scan stepper: reference errors, reversibility, merging, dtypes,
no recompilation, jit/vmap/grad, saving, backward runs, generic PyTree states."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError, RigidBody

REVERSIBILITY_TOL = 1e-14
MERGE_TOL = 1e-12
# The merged run is test_core_conservation.py's: 10⁵ steps of h = 0.1 saved every 100, compared
# after MERGE_STEPS; one compiled program serves both tests (same xdist group, same worker).
MERGE_H, MERGE_STEPS, MERGE_RUN, MERGE_SAVE_EVERY = 0.1, 1000, 100_000, 100
ROUNDOFF = 1e-13
ACCUMULATED_ROUNDOFF = 1e-12  # 2 x 500 steps x 34 rotations
TABLE_RTOL = 0.05  # the reference table prints two significant digits
FD_RTOL = 1e-6

STANDARD = RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)
REFERENCE = np.asarray(jaxsplit.STANDARD_CASE.reference)
SCHEMES = list(jaxsplit.schemes)
SPLITS = [(name, split) for name in SCHEMES for split in ("axes", "casimir")
          if jaxsplit.schemes[name].pieces_allowed(3 if split == "axes" else 2)]


def random_unit_states(n, seed=0):
    m = jax.random.normal(jax.random.PRNGKey(seed), (n, 3))
    return m / jnp.linalg.norm(m, axis=1, keepdims=True)


# (scheme, split, shift axis, steps, error at T = 10) from shared/reference/coefficients.md
REFERENCE_TABLE = [
    ("strang", "axes", None, 320, 3.7e-4), ("strang", "axes", None, 640, 9.2e-5),
    ("triple-jump-4", "axes", None, 160, 6.5e-6), ("suzuki-5", "axes", None, 80, 5.3e-7),
    ("mclachlan-ss5", "axes", None, 80, 2.6e-6), ("mclachlan-m4", "axes", None, 80, 1.4e-6),
    ("blanes-moan-s6", "axes", None, 80, 1.6e-7), ("yoshida-6a", "axes", None, 80, 6.0e-9),
    ("kahan-li-6", "axes", None, 80, 5.7e-9), ("blanes-moan-s10", "axes", None, 40, 2.8e-8),
    ("mclachlan-ss15", "axes", None, 40, 1.2e-9), ("kahan-li-8", "axes", None, 40, 1.1e-10),
    ("sofroniou-spaletta-10", "axes", None, 10, 5.9e-9),
    ("strang", "casimir", 3, 160, 2.6e-4), ("triple-jump-4", "casimir", 3, 160, 2.5e-7),
    ("blanes-moan-s6-prk", "casimir", 3, 80, 1.1e-8), ("kahan-li-6", "casimir", 3, 80, 2.1e-10),
    ("blanes-moan-s10-prk", "casimir", 3, 40, 2.3e-10),
]


def test_automatic_casimir_shift_beats_the_other_axes():
    """The middle axis minimises |c_a c_b|; measured on the standard case at equal cost."""
    errors = {}
    for shift in ("auto", 0, 1, 2):
        step = jaxsplit.splitting(STANDARD, "strang", "casimir", shift=shift)
        errors[shift] = np.abs(np.asarray(jaxsplit.integrate(step, M0, 0.0625, 160).final) - REFERENCE).max()
    assert errors["auto"] == errors[1] < min(errors[0], errors[2])


def test_automatic_shift_is_exact_for_a_symmetric_body():
    body = RigidBody(jnp.asarray(jaxsplit.PAPER_BODY))
    m0 = jnp.asarray(jaxsplit.PAPER_M0)
    step = jaxsplit.splitting(body, "lie-trotter", "casimir")
    exact = jaxsplit.symmetric_solution(body, m0, 50.0)
    assert np.abs(jaxsplit.integrate(step, m0, 0.5, 100).final - exact).max() < ROUNDOFF


def test_rotation_counts_after_merging():
    """Strang: 5 rotations (4 across steps) on the axes split, 3 (2) on the Casimir split."""
    axes = jaxsplit.splitting(STANDARD, "strang")
    casimir = jaxsplit.splitting(STANDARD, "strang", "casimir")
    assert (len(axes.word), axes.flows_per_step) == (5, 4)
    assert (len(casimir.word), casimir.flows_per_step) == (3, 2)
    assert len(jaxsplit.splitting(STANDARD, "strang", merge_flows=False).word) == 6


def rolled_registry(split, merge_flows=None, symmetric_only=False, names=None, **options):
    """Every scheme allowed on ``split`` (or those ``names``) as one rolled family: (names, flows,
    pieces, weights), the words padded to one length, so that a check over the whole registry is
    ONE compilation (``jax.vmap`` over the stacked words) instead of one per scheme."""
    if names is None:
        names = [n for n, s in SPLITS if s == split and (jaxsplit.schemes[n].symmetric or not symmetric_only)]
    comps = [jaxsplit.splitting(STANDARD, n, split, merge_flows=merge_flows, **options) for n in names]
    length = max(len(c.word) for c in comps)
    rolled = [jaxsplit.roll(c, length) for c in comps]
    flows = rolled[0].flows
    assert all(jax.tree_util.tree_structure(r.flows) == jax.tree_util.tree_structure(flows) for r in rolled)
    return names, flows, jnp.stack([r.pieces for r in rolled]), jnp.stack([r.weights for r in rolled])


@functools.cache
def table_errors(split):
    """{(scheme, steps): max |m(10) − reference|} for the table's rows on ``split``: each scheme's
    sub-flows as written (``merge_flows=False``), rolled, every row in ONE compilation: each
    row's step size runs the longest row's step count with every state saved, and its own count
    is read off (a static count per row compiled every row's unrolled stepper anew). The
    stepper users run (unrolled, merged) is tied to these words to 1e-12 by
    ``test_merged_and_unmerged_compositions_agree``."""
    rows = [row for row in REFERENCE_TABLE if row[1] == split]
    (shift,) = {row[2] for row in rows}
    _, flows, pieces, weights = rolled_registry(split, merge_flows=False, names=[row[0] for row in rows],
                                                **({"shift": shift - 1} if shift else {}))
    longest = max(row[3] for row in rows)
    run = jax.jit(jax.vmap(lambda p, w, h: jaxsplit.integrate(
        jaxsplit.RolledComposition(flows, p, w), M0, h, longest, save_every=1).x))
    states = np.asarray(run(pieces, weights, jnp.asarray([10.0 / row[3] for row in rows])))
    return {(name, steps): np.abs(states[k, steps] - REFERENCE).max()
            for k, (name, _, _, steps, _) in enumerate(rows)}


@pytest.mark.parametrize("name, split, shift, steps, expected", REFERENCE_TABLE)
def test_reproduces_the_reference_error_table(name, split, shift, steps, expected):
    """Independent check of composition order and conventions (50-digit-verified table)."""
    error = table_errors(split)[(name, steps)]
    assert abs(error / expected - 1) <= TABLE_RTOL


@functools.cache
def reversal_errors(split):
    """{scheme: worst |step(step(m, h), -h) - m|} over 16 states and h in (1e-3, 0.1, 1), for
    every symmetric scheme allowed on ``split``: the schemes' merged words (exactly the
    sub-flows ``splitting`` applies), rolled, all schemes in one compilation."""
    names, flows, pieces, weights = rolled_registry(split, symmetric_only=True)
    states = random_unit_states(16)

    @jax.jit
    @jax.vmap
    def worst(pieces, weights):
        step = jaxsplit.RolledComposition(flows, pieces, weights)
        there_and_back = jax.vmap(jax.vmap(lambda m, h: step(step(m, h), -h), (0, None)), (None, 0))
        return jnp.abs(there_and_back(states, jnp.array([1e-3, 0.1, 1.0])) - states).max()

    return dict(zip(names, np.asarray(worst(pieces, weights))))


@pytest.mark.parametrize("name, split", [s for s in SPLITS if jaxsplit.schemes[s[0]].symmetric])
def test_symmetric_schemes_are_time_reversible(name, split):
    assert reversal_errors(split)[name] <= REVERSIBILITY_TOL


def test_lie_trotter_is_not_reversible_but_its_adjoint_inverts_it():
    lie = jaxsplit.splitting(STANDARD, "lie-trotter")
    adjoint = jaxsplit.splitting(STANDARD, "lie-trotter-adjoint")
    m = random_unit_states(1)[0]
    assert np.abs(lie(lie(m, 0.1), -0.1) - m).max() > 1e-6
    assert np.abs(adjoint(lie(m, 0.1), -0.1) - m).max() <= REVERSIBILITY_TOL


@functools.cache
def unmerged_finals(split, n_steps=MERGE_STEPS):
    """{scheme: final state} of every scheme allowed on ``split`` with its sub-flows as written
    (``merge_flows=False``): the reference, rolled, all schemes in one compilation."""
    names, flows, pieces, weights = rolled_registry(split, merge_flows=False)
    run = jax.jit(jax.vmap(lambda p, w: jaxsplit.integrate(
        jaxsplit.RolledComposition(flows, p, w), M0, MERGE_H, n_steps).final))
    return dict(zip(names, np.asarray(run(pieces, weights))))


@pytest.mark.parametrize("name, split", [pytest.param(name, split, marks=pytest.mark.xdist_group(f"unrolled-{name}"))
                                         for name, split in SPLITS])
def test_merged_and_unmerged_compositions_agree(name, split):
    """The merged composition as users run it (unrolled, merged across steps by ``advance``)
    against the scheme's sub-flows as written, after MERGE_STEPS steps."""
    merged = jaxsplit.integrate(jaxsplit.splitting(STANDARD, name, split), M0, MERGE_H, MERGE_RUN,
                                save_every=MERGE_SAVE_EVERY)
    assert float(merged.t[MERGE_STEPS // MERGE_SAVE_EVERY]) == pytest.approx(MERGE_STEPS * MERGE_H, rel=1e-15)
    a = merged.x[MERGE_STEPS // MERGE_SAVE_EVERY]
    assert np.abs(a - unmerged_finals(split)[name]).max() <= MERGE_TOL


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_output_dtype_follows_the_input(dtype):
    step = jaxsplit.splitting(STANDARD, "kahan-li-6", "casimir")
    x = M0.astype(dtype)
    assert step(x, 0.1).dtype == dtype
    assert jaxsplit.integrate(step, x, 0.1, 10).final.dtype == dtype
    traj = jaxsplit.integrate(step, x, 0.1, 10, save_every=3)
    assert traj.x.dtype == dtype and traj.t.dtype == dtype


def test_a_new_step_size_or_body_does_not_recompile():
    """New values of h (of any size: no angle bound is consulted) and of the inertia reuse the
    compiled loop; only static sizes compile."""
    step, other = jaxsplit.splitting(STANDARD, "strang"), jaxsplit.splitting(RigidBody([3.0, 2.0, 1.0]), "strang")
    jaxsplit.integrate(step, M0, 0.1, 50)
    compiled = jaxsplit.core._integrate.compilations()
    for s, h in [(step, 0.09), (other, -0.2), (step, 40.0), (other, -50.0)]:
        jaxsplit.integrate(s, M0, h, 50)
    assert jaxsplit.core._integrate.compilations() == compiled
    jaxsplit.integrate(step, M0, 0.1, 51)  # the step count is static: this one compiles
    assert jaxsplit.core._integrate.compilations() == compiled + 1


def test_vmap_over_initial_conditions_and_bodies_matches_a_loop():
    states = random_unit_states(4, seed=1)
    inertias = jnp.array([[2.0, 1.0, 0.7], [1.0, 1.5, 2.0], [3.0, 2.5, 1.0], [1.2, 1.1, 1.0]])

    def run(inertia, m0):
        step = jaxsplit.splitting(RigidBody(inertia, allow_nonphysical=True), "blanes-moan-s6-prk", "casimir", shift=1)
        return jaxsplit.integrate(step, m0, 0.05, 200).final

    batched = jax.jit(jax.vmap(run))(inertias, states)
    looped = jnp.stack([run(i, m) for i, m in zip(inertias, states)])
    assert np.abs(batched - looped).max() <= ROUNDOFF


def test_gradient_through_the_integrator_matches_finite_differences():
    def loss(inertia, m0):
        step = jaxsplit.splitting(RigidBody(inertia, allow_nonphysical=True), "strang")
        return jnp.sum(jaxsplit.integrate(step, m0, 0.05, 400).final ** 3)

    inertia = jnp.asarray(jaxsplit.STANDARD_CASE.inertia)
    grads = jax.grad(loss, argnums=(0, 1))(inertia, M0)
    for arg, grad in enumerate(grads):
        for k in range(3):
            e = jnp.zeros(3).at[k].set(1e-6)
            args_plus = [inertia, M0]
            args_minus = [inertia, M0]
            args_plus[arg] = args_plus[arg] + e
            args_minus[arg] = args_minus[arg] - e
            fd = (loss(*args_plus) - loss(*args_minus)) / 2e-6
            assert abs(grad[k] - fd) <= FD_RTOL * max(1.0, abs(fd))


def test_negative_step_integrates_backwards():
    step = jaxsplit.splitting(STANDARD, "kahan-li-8", "casimir")
    there = jaxsplit.integrate(step, M0, 0.1, 500).final
    back = jaxsplit.integrate(step, there, -0.1, 500).final
    assert np.abs(back - M0).max() <= ACCUMULATED_ROUNDOFF


def test_saving_keeps_the_start_every_kth_state_and_the_end():
    step = jaxsplit.splitting(STANDARD, "strang")
    traj = jaxsplit.integrate(step, M0, 0.1, 10, save_every=4)
    np.testing.assert_allclose(traj.t, [0.0, 0.4, 0.8, 1.0], rtol=1e-15)
    for t, x in zip(traj.t, traj.x):
        n = round(float(t) / 0.1)
        assert np.abs(x - jaxsplit.integrate(step, M0, 0.1, n).final).max() <= ROUNDOFF
    assert jaxsplit.integrate(step, M0, 0.1, 0).final is not None


@pytest.mark.parametrize("bad", [-1, 2.5, True, "10"])
def test_bad_step_counts_are_refused(bad):
    step = jaxsplit.splitting(STANDARD, "strang")
    with pytest.raises(InputError, match="n_steps"):
        jaxsplit.integrate(step, M0, 0.1, bad)
    with pytest.raises(InputError, match="save_every"):
        jaxsplit.integrate(step, M0, 0.1, 10, save_every=0)


def test_composer_is_generic_over_pytree_states_and_user_flows():
    """Harmonic oscillator as drift and kick on a dict state: Strang is the leapfrog."""

    def drift(state, t, params):
        return {"q": state["q"] + t * state["p"], "p": state["p"]}

    def kick(state, t, params):
        return {"q": state["q"], "p": state["p"] - t * params * state["q"]}

    x0 = {"q": jnp.array(1.0), "p": jnp.array(0.0)}
    errors = []
    for n in (100, 200):
        step = jaxsplit.compose([kick, drift], "strang", params=jnp.array(1.0))
        x = jaxsplit.integrate(step, x0, 1.0 / n, n).final
        errors.append(abs(float(x["q"]) - np.cos(1.0)))
    assert abs(np.log2(errors[0] / errors[1]) - 2) < 0.05


def test_any_pure_function_can_be_stepped():
    def euler(m, h):
        return m + h * STANDARD.vector_field(m)

    m = jaxsplit.integrate(euler, M0, 0.01, 100).final
    assert float(jnp.sum(m * m)) > float(jnp.sum(M0 * M0))  # Euler inflates |m|
