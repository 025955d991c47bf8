"""jaxsplit inside diffrax (issue 11): the ``Splitting`` solver against ``jaxsplit.integrate``.

Acceptance: identical final states to round-off for every registered scheme on the free body
and on one other system (a pendulum, canonical and with a PyTree state); SaveAt outputs at 50
arbitrary times on the Casimir's level set; gradients through ``diffeqsolve`` equal to those
through ``integrate``; vmap, progress meter, backward time, dense output, adaptive control.
Every scheme runs through ``RolledSplitting`` (one compilation, vmapped over the registry);
the default ``Splitting`` is checked on one scheme of each form. SaveAt, dense output and
events run the rolled Kahan–Li 6 (``rolled_kl6``): the partial steps are the solvers' shared
code, and the rolled word compiles several times faster (the PartialStep doctest runs
``Splitting``'s dense output).
"""

import subprocess
import sys

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
import jaxsplit.diffrax as jd
from jaxsplit import InputError

SAME = 1e-14  # acceptance: final states identical to round-off (relative to the largest component)
CASIMIR_TOL = 1e-13  # acceptance: |C(x(t)) / C(x0) - 1| at the SaveAt times
GRAD_TOL = 1e-10  # acceptance: gradients through diffeqsolve vs through integrate (relative)
HERMITE_FLOOR = 1e-8  # a cubic interpolant at h = 0.125 leaves the sphere by far more than this
# A dyadic step: diffrax's grid t0 + (t1 - t0) k / n is then exactly k h, the grid of ``integrate``.
# With h = 0.1 the grids differ by ulps and the results by up to 1.1e-13 on the pendulum
# (1.5e-14 on the body): time-grid round-off, not the map (benchmarks/diffrax_overhead.py).
H, T_END, N = 0.125, 10.0, 80
CASE = jaxsplit.STANDARD_CASE
BODY = jaxsplit.RigidBody(jnp.asarray(CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(CASE.m0)
SHIFT = 1  # the middle 1/I axis of the standard body: what shift="auto" picks
ONE_PER_FORM = ("lie-trotter", "kahan-li-6", "blanes-moan-s6", "blanes-moan-s6-prk")


# ------------------------------------------------------------------ a second system
class Drift(jaxsplit.AbstractFlow):
    def __call__(self, x, t):
        q, p = x
        return q + t * p, p


class Kick(jaxsplit.AbstractFlow):
    omega2: jax.Array

    def __call__(self, x, t):
        q, p = x
        return q, p - t * self.omega2 * jnp.sin(q)


class Pendulum(jaxsplit.AbstractSystem):
    """H = p²/2 − ω² cos q on x = (q, p): drift and kick are exact shears (group flows)."""

    omega2: jax.Array

    def hamiltonian(self, x):
        return 0.5 * x[1] ** 2 - self.omega2 * jnp.cos(x[0])

    def poisson_matrix(self, x):
        return jnp.array([[0.0, 1.0], [-1.0, 0.0]], dtype=x[0].dtype)

    def splits(self):
        return {"drift-kick": lambda: (Drift(), Kick(self.omega2))}


PENDULUM = Pendulum(jnp.asarray(2.0))
X0 = (jnp.asarray(1.2), jnp.asarray(0.3))

CASES = {  # name: (system, split options, initial state)
    "rigid-body": (BODY, {"split": "casimir", "shift": SHIFT}, M0),
    "pendulum": (PENDULUM, {}, X0),
}


def solve(term, solver, y0, t0=0.0, t1=T_END, dt0=H, **kw):
    return diffrax.diffeqsolve(term, solver, t0, t1, dt0, y0, **kw)


def last(tree):
    return jax.tree_util.tree_map(lambda a: a[-1], tree)


def row(tree, k):
    return jax.tree_util.tree_map(lambda a: a[k], tree)


def max_diff(a, b):
    """max |a - b| over the leaves, relative to max |b| (round-off is relative)."""
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    scale = max(float(jnp.max(jnp.abs(v))) for v in lb)
    return max(float(jnp.max(jnp.abs(u - v))) for u, v in zip(la, lb)) / scale


def casimir_drift(ms, m0):
    return float(jnp.max(jnp.abs(jnp.sum(ms * ms, axis=-1) / jnp.sum(m0 * m0) - 1)))


# ------------------------------------------------------------------ every scheme
@pytest.mark.parametrize("case", CASES)
def test_every_scheme_matches_integrate(case):
    """All registered schemes in one compilation per side: rolled words, vmapped over schemes."""
    system, options, x0 = CASES[case]
    term = jd.term(system, **options)
    names = list(jaxsplit.schemes)
    length = max(len(jaxsplit.splitting(system, n, **options).word) for n in names)
    solvers = [jd.RolledSplitting.of(n, term, length) for n in names]
    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *solvers)
    ours = jax.vmap(lambda s: last(solve(term, s, x0).ys))(stacked)
    ref = jax.vmap(lambda p, w: jaxsplit.integrate(jaxsplit.RolledComposition(term.flows, p, w), x0, H, N).final)(
        stacked.pieces, stacked.weights)
    errors = {n: max_diff(row(ours, k), row(ref, k)) for k, n in enumerate(names)}
    assert max(errors.values()) <= SAME, errors
    # must-fail: another scheme's result is far from "the same" (the check can fail)
    assert max_diff(row(ours, names.index("strang")), row(ref, names.index("kahan-li-6"))) > 1e3 * SAME


@pytest.mark.parametrize("scheme", ONE_PER_FORM[:2])
def test_splitting_matches_integrate_on_the_pendulum(scheme):
    term = jd.term(PENDULUM)
    ours = last(solve(term, jd.Splitting(scheme), X0).ys)
    ref = jaxsplit.integrate(jaxsplit.splitting(PENDULUM, scheme), X0, H, N).final
    assert isinstance(ours, tuple) and max_diff(ours, ref) <= SAME


def test_partitioned_schemes_on_three_pieces_are_refused_before_stepping():
    term = jd.term(BODY, split="axes")
    with pytest.raises(InputError, match="needs exactly 2 pieces"):
        solve(term, jd.Splitting("blanes-moan-s6-prk"), M0)


# ------------------------------------------------------------------ SaveAt, dense output
def rolled_kl6():
    """(term, diffrax solver, jaxsplit step): Kahan–Li 6 on the free body's Casimir split, rolled."""
    term = jd.term(BODY, split="casimir", shift=SHIFT)
    step = jaxsplit.roll(jaxsplit.splitting(BODY, "kahan-li-6", "casimir", shift=SHIFT))
    return term, jd.RolledSplitting(step.pieces, step.weights), step


@pytest.fixture(scope="module")
def saved():
    """Kahan–Li 6 on the free body with SaveAt(ts=50 random times, t1=True, steps=True)."""
    ts = jnp.sort(jax.random.uniform(jax.random.PRNGKey(0), (50,), minval=0.0, maxval=T_END))
    term, solver, _ = rolled_kl6()
    sol = solve(term, solver, M0, saveat=diffrax.SaveAt(ts=ts, t1=True, steps=True))
    keep = np.isfinite(np.asarray(sol.ts))  # diffrax pads the steps buffer with inf
    return ts, np.asarray(sol.ts)[keep], sol.ys[keep]


def test_splitting_matches_integrate_for_one_scheme_of_each_form_on_the_body():
    term = jd.term(BODY, split="casimir", shift=SHIFT)
    for scheme in ONE_PER_FORM[2:]:
        ours = last(solve(term, jd.Splitting(scheme), M0).ys)
        ref = jaxsplit.integrate(jaxsplit.splitting(BODY, scheme, "casimir", shift=SHIFT), M0, H, N).final
        assert max_diff(ours, ref) <= SAME, scheme


def test_saveat_ts_steps_t1_are_partial_steps_on_the_leaf(saved):
    ts, times, ys = saved
    # the steps' states include t1 = T_END (diffrax saves it once)
    assert len(times) == 50 + N and np.all(np.diff(times) >= 0) and times[-1] == T_END
    assert np.all(np.isin(np.asarray(ts), times))
    _, _, step = rolled_kl6()
    ref = jaxsplit.integrate(step, M0, H, ts=jnp.asarray(times))  # grid points are 0-length partial steps
    assert max_diff(ys, ref.x) <= SAME
    assert max_diff(ys[-1], jaxsplit.integrate(step, M0, H, N).final) <= SAME
    assert casimir_drift(ys, M0) <= CASIMIR_TOL


def test_polynomial_dense_output_leaves_the_leaf(saved):
    """Must-fail twin of the partial step: diffrax's cubic Hermite interpolant between the same
    grid states (the usual dense output of an ODE solver) does not keep the Casimir."""
    ts, times, ys = saved
    grid = ys[np.isin(times, np.arange(N + 1) * T_END / N)]
    k = np.minimum(np.floor(np.asarray(ts) / H).astype(int), N - 1)

    def hermite(t, y0, y1):
        f0, f1 = BODY.vector_field(y0), BODY.vector_field(y1)
        return diffrax.ThirdOrderHermitePolynomialInterpolation(
            t0=0.0, t1=H, y0=y0, y1=y1, k0=H * f0, k1=H * f1).evaluate(t)

    poly = jax.vmap(hermite)(jnp.asarray(ts) - k * H, grid[k], grid[k + 1])
    assert casimir_drift(poly, M0) > HERMITE_FLOOR


# diffrax fills its dense-output buffers with inf, the rolled word's int32 pieces too (harmless)
@pytest.mark.filterwarnings("ignore:invalid value encountered in cast:RuntimeWarning")
def test_dense_output_and_backward_time_match_integrate():
    term, solver, step = rolled_kl6()
    sol = solve(term, solver, M0, t0=T_END, t1=0.0, dt0=-H, saveat=diffrax.SaveAt(dense=True))
    ts = jnp.linspace(T_END, 0.0, 23)
    dense = jax.vmap(sol.evaluate)(ts)
    ref = jaxsplit.integrate(step, M0, -H, ts=ts, t0=T_END)
    assert max_diff(dense, ref.x) <= SAME
    assert casimir_drift(dense, M0) <= CASIMIR_TOL


# ------------------------------------------------------------------ gradients, vmap, progress
def _loss_diffrax(adjoint):
    def loss(inertia, m0):
        term = jd.term(jaxsplit.RigidBody(inertia), split="casimir", shift=SHIFT)
        return jnp.sum(jnp.sin(last(solve(term, jd.Splitting("strang"), m0, adjoint=adjoint).ys)))
    return loss


def _loss_integrate(inertia, m0):
    step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=SHIFT)
    return jnp.sum(jnp.sin(jaxsplit.integrate(step, m0, H, N).final))


_grad_integrate = jax.jit(jax.grad(_loss_integrate, argnums=(0, 1)))  # one compilation for every use below


@pytest.mark.parametrize("adjoint", [diffrax.RecursiveCheckpointAdjoint(), diffrax.RecursiveCheckpointAdjoint(10)],
                         ids=["default", "checkpoints=10"])
def test_gradients_through_diffeqsolve_equal_those_through_integrate(adjoint):
    inertia = jnp.asarray(CASE.inertia)
    ours = jax.grad(_loss_diffrax(adjoint), argnums=(0, 1))(inertia, M0)
    ref = _grad_integrate(inertia, M0)
    for a, b in zip(ours, ref):
        assert float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b))) <= GRAD_TOL
    # must-fail: the gradient is not trivially the same for another body
    other = _grad_integrate(inertia * 1.01, M0)[0]
    assert float(jnp.max(jnp.abs(other - ref[0]))) > 1e3 * GRAD_TOL


def test_vmap_over_bodies_and_states_with_a_progress_meter(capfd):
    inertias = jnp.asarray([[2.0, 1.0, 2 / 3], [3.0, 2.0, 1.5], [1.2, 1.0, 0.8]])
    m0s = jnp.asarray([CASE.m0, [0.2, 0.9, 0.3], [0.6, 0.0, 0.8]])

    def ours(inertia, m0):
        term = jd.term(jaxsplit.RigidBody(inertia), split="casimir", shift=SHIFT)
        return last(solve(term, jd.Splitting("strang"), m0, progress_meter=diffrax.TextProgressMeter()).ys)

    def ref(inertia, m0):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=SHIFT)
        return jaxsplit.integrate(step, m0, H, N).final

    assert max_diff(jax.vmap(ours)(inertias, m0s), jax.vmap(ref)(inertias, m0s)) <= SAME
    assert "100.00%" in capfd.readouterr().out


def test_events_are_located_on_partial_steps():
    import optimistix as optx

    term, solver, _ = rolled_kl6()
    event = diffrax.Event(lambda t, y, args, **kw: y[1] - 0.2, root_finder=optx.Newton(1e-12, 1e-12))
    sol = solve(term, solver, M0, event=event)
    assert 0.0 < float(sol.ts[-1]) < T_END and abs(float(sol.ys[-1, 1]) - 0.2) <= 1e-12
    assert casimir_drift(sol.ys, M0) <= CASIMIR_TOL


def test_backsolve_adjoint_gradient_is_refused_by_diffrax():
    def loss(inertia):
        term = jd.term(jaxsplit.RigidBody(inertia), split="casimir", shift=SHIFT)
        return jnp.sum(solve(term, jd.Splitting("strang"), M0, t1=1.0, adjoint=diffrax.BacksolveAdjoint()).ys)

    with pytest.raises(InputError, match="BacksolveAdjoint"):
        jax.grad(loss)(jnp.asarray(CASE.inertia))


def test_the_core_package_does_not_need_diffrax():
    code = ("import sys; sys.modules['diffrax'] = None; import jaxsplit\n"
            "try:\n    import jaxsplit.diffrax\nexcept ImportError as e:\n    print(e)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert 'pip install -e ".[diffrax]"' in out


# ------------------------------------------------------------------ what is refused, adaptive steps
def test_adaptive_control_needs_an_error_estimate():
    term = jd.term(BODY, split="casimir", shift=SHIFT)
    pid = diffrax.PIDController(rtol=1e-8, atol=1e-8)
    with pytest.raises(RuntimeError, match="error estimates"):
        solve(term, jd.Splitting("strang"), M0, stepsize_controller=pid)
    # step doubling (diffrax.HalfSolver) gives one: every step is still Poisson
    sol = solve(term, diffrax.HalfSolver(jd.Splitting("kahan-li-6")), M0, stepsize_controller=pid)
    error = max_diff(last(sol.ys), jnp.asarray(CASE.reference))
    assert error <= 1e3 * 1e-8 and casimir_drift(sol.ys, M0) <= CASIMIR_TOL
    assert int(sol.stats["num_accepted_steps"]) != N  # it did adapt


def test_bad_input_is_refused_with_one_line():
    term = jd.term(BODY, split="casimir", shift=SHIFT)
    with pytest.raises(InputError, match="args=None"):
        solve(term, jd.Splitting("strang"), M0, args=(1.0,))
    with pytest.raises(InputError, match="system of the system layer"):
        jd.term(jnp.asarray([2.0, 1.0, 0.5]))
    with pytest.raises(InputError, match="not offered"):
        jd.term(BODY, split="nope")
    with pytest.raises(InputError, match="unknown scheme|not a registered|scheme"):
        jd.Splitting("no-such-scheme")
    with pytest.raises(InputError, match="jd.term"):  # not diffrax's bare "not compatible with solver"
        solve(diffrax.ODETerm(lambda t, y, a: BODY.vector_field(y)), jd.Splitting("strang"), M0)
