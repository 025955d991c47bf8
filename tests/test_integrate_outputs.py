"""integrate's one result type, output at arbitrary times, and the three adjoints."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError
from jaxsplit.core import _adjoints
from jaxsplit.core._integrate import compilations

CASIMIR_TOL = 1e-13  # relative, states at output times (partial steps are Poisson maps)
ACCURACY_FACTOR = 1.5  # error at output times vs the grid's own error (same scheme, same h)
GRADIENT_RTOL = 1e-8  # reversible vs stored gradient, 1e5 steps (round-off of the rebuilt states)
FD_RTOL = 1e-6
FLOAT32_DRIFT_SEEN = 1e-5  # Kahan-Li 6, axes, 2e4 float32 steps, largest of 16-64 states: measured 3e-5 to 7e-5
FLOAT32_PROJECTED = 1e-6  # |m| projected back each step: float32 round-off (3e-7) only
FLOAT32_ENERGY_RATIO = 1.5  # median energy error projected / plain, 64 states: measured 0.50 to 0.83 (6 seeds)

BODY = jaxsplit.RigidBody(jnp.asarray(jaxsplit.PAPER_BODY))  # symmetric: exact solution known
M0 = jnp.asarray(jaxsplit.PAPER_M0)
STANDARD = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
SM0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)


def test_one_result_type():
    step = jaxsplit.splitting(STANDARD, "strang", "casimir")
    plain = jaxsplit.integrate(step, SM0, 0.1, 100)
    saved = jaxsplit.integrate(step, SM0, 0.1, 100, save_every=30)
    assert isinstance(plain, jaxsplit.Solution) and isinstance(saved, jaxsplit.Solution)
    # the same steps; saving splits the scan in blocks, which XLA may fuse differently (an ulp)
    np.testing.assert_allclose(plain.final, saved.final, rtol=0, atol=4 * np.finfo(np.float64).eps)
    np.testing.assert_array_equal(plain.x[0], SM0)
    np.testing.assert_allclose(plain.t, [0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(saved.t, [0.0, 3.0, 6.0, 9.0, 10.0], atol=1e-12)
    assert (plain.n_steps, plain.scheme, plain.status) == (100, "strang", "ok")
    assert float(plain.h) == 0.1
    shifted = jaxsplit.integrate(step, SM0, 0.1, 100, t0=5.0)
    np.testing.assert_allclose(shifted.t, [5.0, 15.0], atol=1e-12)
    # vmap gives a batched Solution
    batch = jax.vmap(lambda h: jaxsplit.integrate(step, SM0, h, 10))(jnp.array([0.1, 0.2]))
    assert batch.final.shape == (2, 3) and batch.t.shape == (2, 2)
    # a blow-up is reported, not hidden
    blown = jaxsplit.integrate(lambda x, h: 1e200 * x, SM0, 0.1, 5)
    assert blown.status == "nonfinite" and not bool(blown.finite)


_exact = jax.jit(lambda t: jaxsplit.symmetric_solution(BODY, M0, t))  # one program per length (op by op: ~15)


@pytest.fixture(scope="module")
def outputs_case():
    step = jaxsplit.splitting(BODY, "suzuki-5", "axes")  # axes split: not exact for this body
    h, n = 0.05, 400
    grid = jaxsplit.integrate(step, M0, h, n, save_every=1)
    grid_error = float(np.max(np.abs(np.asarray(grid.x) - np.asarray(_exact(grid.t)))))
    return step, h, n, grid_error, np.asarray(grid.x)


def test_states_at_1000_random_times(outputs_case):
    step, h, n, grid_error, grid = outputs_case
    rng = np.random.default_rng(0)
    ts = np.sort(rng.uniform(0.0, h * n, 1000))
    sol = jaxsplit.integrate(step, M0, h, ts=ts)
    exact = _exact(sol.t)
    error = np.max(np.abs(np.asarray(sol.x) - np.asarray(exact)), axis=1)
    assert grid_error > 1e-12  # the comparison is not trivial
    assert np.max(error) <= ACCURACY_FACTOR * grid_error, (np.max(error), grid_error)
    c0 = float(M0 @ M0)
    casimir = np.abs(np.sum(np.asarray(sol.x) ** 2, axis=1) / c0 - 1)
    assert np.max(casimir) <= CASIMIR_TOL
    # one compilation for a new set of times of the same length (and a new h)
    before = compilations()
    jaxsplit.integrate(step, M0, 0.04, ts=np.sort(rng.uniform(0.0, 20.0, 1000)))
    # outputs on the grid are the grid states (1000 times again: the same compiled program)
    on_grid = np.array([0.0, 1.0, 20.0])
    ts = np.sort(np.concatenate([on_grid, rng.uniform(0.0, 20.0, 997)]))
    at = np.asarray(jaxsplit.integrate(step, M0, h, ts=ts).x)[np.searchsorted(ts, on_grid)]
    assert compilations() == before
    np.testing.assert_allclose(at, grid[[0, 20, 400]], atol=1e-14)


def test_output_times_are_checked():
    step = jaxsplit.splitting(BODY, "strang")
    with pytest.raises(InputError, match="ordered"):
        jaxsplit.integrate(step, M0, 0.1, ts=[1.0, 0.5])
    with pytest.raises(InputError, match="ordered"):
        jaxsplit.integrate(step, M0, -0.1, ts=[1.0])  # backwards run, forward time
    with pytest.raises(InputError, match="finite"):
        jaxsplit.integrate(step, M0, 0.1, ts=[0.5, np.nan])
    with pytest.raises(InputError, match="either ts="):
        jaxsplit.integrate(step, M0, 0.1, 10, ts=[0.5])
    with pytest.raises(InputError, match="needs n_steps"):
        jaxsplit.integrate(step, M0, 0.1)
    with pytest.raises(InputError, match="at most 2\\^31 - 1 steps"):  # the grid index is an int32: no wrap-around
        jaxsplit.integrate(step, M0, 0.1, ts=[0.5, 2.0**31 * 0.1])
    with pytest.raises(InputError, match="non-zero step size"):  # h = 0: no grid at all
        jaxsplit.integrate(step, M0, 0.0, ts=[0.5, 1.0])
    back = jaxsplit.integrate(step, M0, -0.1, ts=[-0.25, -1.0])  # backwards: decreasing times
    np.testing.assert_allclose(back.t, [-0.25, -1.0])


def _loss(adjoint, n, steps=None):
    def loss(inertia, m0):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
        return jnp.sum(jaxsplit.integrate(step, m0, 0.01, n, adjoint=adjoint).final ** 2 * jnp.arange(1.0, 4.0))
    return loss


GRADIENT_ARGS = (jnp.asarray(jaxsplit.STANDARD_CASE.inertia), SM0)


@functools.cache
def _compiled_gradient(adjoint, n):
    """The gradient of ``_loss(adjoint, n)`` in (inertia, m0), compiled once: the agreement and the
    memory tests below share the 1e5-step programs (one xdist worker runs both)."""
    return jax.jit(jax.grad(_loss(adjoint, n), argnums=(0, 1))).lower(*GRADIENT_ARGS).compile()


@pytest.mark.xdist_group("adjoint-gradients")
def test_adjoints_agree_over_1e5_steps():
    stored = _compiled_gradient("store", 100_000)(*GRADIENT_ARGS)
    for adjoint in ("checkpoint", "reversible"):
        got = _compiled_gradient(adjoint, 100_000)(*GRADIENT_ARGS)
        for g, s in zip(got, stored):
            assert float(jnp.max(jnp.abs(g - s)) / jnp.max(jnp.abs(s))) <= GRADIENT_RTOL, adjoint


@pytest.mark.xdist_group("adjoint-gradients")
def test_reversible_memory_does_not_grow_with_the_step_count():
    sizes = {}
    for adjoint in ("store", "reversible"):
        for n in (1_000, 100_000):
            sizes[adjoint, n] = _compiled_gradient(adjoint, n).memory_analysis().temp_size_in_bytes
    assert sizes["reversible", 100_000] == sizes["reversible", 1_000]
    # the stored adjoint does grow: it keeps one state (24 bytes) in KEEP_EVERY steps
    assert sizes["store", 100_000] > max(20 * sizes["store", 1_000], 100_000 // _adjoints.KEEP_EVERY * 24)


def test_reversible_gradient_at_output_times_matches_finite_differences():
    step = jaxsplit.splitting(STANDARD, "suzuki-5", "casimir")
    ts = jnp.array([0.37, 1.2, 3.05])

    @jax.jit
    def loss(m0):
        return jnp.sum(jaxsplit.integrate(step, m0, 0.1, ts=ts, adjoint="reversible").x[:, 0])

    g = jax.jit(jax.grad(loss))(SM0)
    eps, m0 = 1e-6, np.asarray(SM0)
    fd = [(float(loss(m0 + eps * e)) - float(loss(m0 - eps * e))) / (2 * eps) for e in np.eye(3)]
    np.testing.assert_allclose(g, fd, rtol=FD_RTOL, atol=1e-9)


def test_reversible_adjoint_is_refused_where_it_is_wrong():
    with pytest.raises(InputError, match="Composition"):
        jaxsplit.integrate(jaxsplit.rk4(STANDARD), SM0, 0.1, 10, adjoint="reversible")
    inner = jaxsplit.splitting(STANDARD, "lie-trotter")  # not time-symmetric: Ψ_-h is not Ψ_h⁻¹
    with pytest.raises(InputError, match="φ_-t = φ_t⁻¹"):
        jaxsplit.integrate(jaxsplit.compose([inner, *STANDARD.split("axes")], "strang"), SM0, 0.1, 10,
                           adjoint="reversible")
    projected = jaxsplit.compose([jaxsplit.Renormalized(jaxsplit.splitting(STANDARD, "strang"), 1.0)], "strang")
    with pytest.raises(InputError, match="Renormalized is not"):
        jaxsplit.integrate(projected, SM0, 0.1, 10, adjoint="reversible")
    with pytest.raises(InputError, match="adjoint must be one of"):
        jaxsplit.integrate(inner, SM0, 0.1, 10, adjoint="recompute")


def test_float32_casimir_drift_and_the_opt_in_projection():
    """float32 round-off drifts |m| over 2e4 steps of a high-order scheme; Renormalized projects
    it back (a projection, reported as such) and leaves the energy error no worse. Measured on an
    ensemble of 64 states (one state's float32 errors are a coin toss: CI's rounding differs)."""
    body32 = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia, dtype=jnp.float32), allow_nonphysical=True)
    m = np.random.default_rng(0).normal(size=(64, 3))
    m32 = jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True), dtype=jnp.float32)
    step = jaxsplit.splitting(body32, "kahan-li-6", "axes")
    projected = jaxsplit.Renormalized(step, jnp.linalg.norm(m32, axis=-1))
    @jax.jit
    def measure(x32):  # one program for both runs (op by op: ~20)
        x = x32.astype(jnp.float64)
        c, h = jnp.sum(x**2, axis=-1), STANDARD.hamiltonian(x)
        return jnp.max(jnp.abs(c / c[0] - 1)), jnp.median(jnp.max(jnp.abs(h / h[0] - 1), axis=0))

    drift, energy = {}, {}
    for name, s in (("plain", step), ("projected", projected)):
        sol = jaxsplit.integrate(s, m32, 0.1, 20_000, save_every=2_000)
        assert sol.x.dtype == jnp.float32
        drift[name], energy[name] = map(float, measure(sol.x))
    assert drift["plain"] >= FLOAT32_DRIFT_SEEN  # the drift exists and is measured
    assert drift["projected"] <= FLOAT32_PROJECTED
    assert energy["projected"] <= FLOAT32_ENERGY_RATIO * energy["plain"]
    with pytest.raises(InputError, match="does not fit states of batch shape"):  # (16, 1) would broadcast
        jaxsplit.integrate(jaxsplit.Renormalized(step, jnp.linalg.norm(m32, axis=-1, keepdims=True)), m32, 0.1, 2)
    assert projected.scheme.name == "kahan-li-6" and not projected.is_group
