"""The paper's classical integrators: Runge–Kutta methods from tableaus, the Ruth map,
Hamilton–Poisson systems.

Oracles (shared/reference/rigid-body.md): methods satisfying (2.7) keep every quadratic
invariant (H and C of the rigid body) to round-off, the trapezoidal rule does not (~1e-4
at h = 0.1 over T = 1000); explicit Euler obeys |m_{n+1}|² − |m_n|² = h²|f(m_n)|² exactly.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import (
    STANDARD_CASE,
    RigidBody,
    example_3_1,
    explicit_euler,
    gauss_legendre,
    integrate,
    monitor_invariants,
    rigid_body_system,
    rk4,
    runge_kutta,
    ruth,
    trapezoid,
)

QUADRATIC_INVARIANT_TOL = 1e-13  # GL over 1e4 steps, absolute (H, C ~ 0.5)
TRAPEZOID_FLOOR = 1e-6  # the trapezoidal rule's invariant errors are ~1e-4
EULER_IDENTITY_TOL = 2 * 2 * 2.2e-16  # two ulps of the largest sum, |m + h f|² <= 2 (measured 4.1e-16 without FMAs)
NEWTON_TOL = 1e-15  # stage residual after the solve, states of size ~1
FD_TOL = 1e-7  # central differences with step 1e-5: truncation ~1e-10, round-off ~1e-11
ORDER_TOL = 0.3
NEWTON_UNCONVERGED = 1e-8  # residual after one Newton iteration at h = 0.5
FIELD_TOL = 1e-15

BODY = RigidBody(jnp.array(STANDARD_CASE.inertia), allow_nonphysical=True)
M0 = jnp.array(STANDARD_CASE.m0)
REFERENCE = jnp.array(STANDARD_CASE.reference)


def _states(n, seed=0):
    x = jax.random.normal(jax.random.PRNGKey(seed), (n, 3))
    return x / jnp.linalg.norm(x, axis=1, keepdims=True)


# One compiled monitor for every trajectory of 101 saved states (op by op it compiled ~40 programs).
_monitor = jax.jit(lambda traj: monitor_invariants(BODY, traj))


@pytest.mark.parametrize("stages", [1, 2, 3])
def test_gauss_legendre_keeps_quadratic_invariants(stages):
    traj = integrate(gauss_legendre(BODY, stages), M0, 0.1, 10_000, save_every=100)
    errors = _monitor(traj)
    assert float(errors["energy"].max_absolute) <= QUADRATIC_INVARIANT_TOL
    assert float(errors["casimir"].max_absolute) <= QUADRATIC_INVARIANT_TOL


def test_trapezoid_does_not_keep_them():
    traj = integrate(trapezoid(BODY), M0, 0.1, 10_000, save_every=100)
    errors = _monitor(traj)
    assert float(errors["energy"].max_absolute) >= TRAPEZOID_FLOOR
    assert float(errors["casimir"].max_absolute) >= TRAPEZOID_FLOOR


def test_explicit_euler_norm_identity():
    step = explicit_euler(BODY)
    xs, hs = _states(128), jnp.linspace(1e-3, 1.0, 128)

    def residual(m, h):
        f = BODY.vector_field(m)
        return jnp.abs(jnp.sum(step(m, h) ** 2) - jnp.sum(m**2) - h**2 * jnp.sum(f**2))

    @jax.jit
    def measure(xs, hs):  # one program (op by op: ~20)
        return jnp.max(jax.vmap(residual)(xs, hs)), jnp.min(jax.vmap(lambda m, h: jnp.sum(step(m, h) ** 2) - 1)(xs, hs))

    worst, growth = measure(xs, hs)
    assert float(worst) <= EULER_IDENTITY_TOL
    # and |m| strictly grows: the identity is not vacuous
    assert float(growth) > 0


@pytest.mark.parametrize("name", ["implicit-midpoint", "gauss-legendre-3", "radau-iia-2", "lobatto-iiia-3"])
def test_newton_converges_to_round_off(name):
    step = runge_kutta(BODY, name)
    one_iteration = runge_kutta(BODY, name, max_iter=1)
    a = jnp.asarray(step.tableau.a)

    @jax.jit
    def measure(xs):
        info = jax.vmap(step.newton_info, in_axes=(0, None))(xs, 0.5)
        k = step.stage_derivatives(M0, 0.5)  # through custom_root, as the step uses it
        stage_residual = jnp.max(jnp.abs(k - jax.vmap(BODY.vector_field)(M0 + 0.5 * a @ k)))
        return info, stage_residual, one_iteration.newton_info(M0, 0.5).residual

    info, stage_residual, unconverged = measure(_states(32))
    assert float(jnp.max(info.residual)) <= NEWTON_TOL
    assert int(jnp.max(info.iterations)) < step.max_iter
    assert float(stage_residual) <= NEWTON_TOL
    # must fail: a single Newton iteration leaves a residual far above round-off
    assert float(unconverged) >= NEWTON_UNCONVERGED


def _loss(m0, h, inertia):
    step = gauss_legendre(RigidBody(inertia), 2)
    m = integrate(step, m0, h, 20).final
    return m[0] + 2 * m[1] ** 2 - m[2]


def test_gradients_match_finite_differences():
    args = (M0, jnp.asarray(0.1), jnp.asarray(STANDARD_CASE.inertia))
    grads = jax.jit(jax.grad(_loss, argnums=(0, 1, 2)))(*args)
    loss = jax.jit(_loss)  # one compilation for the 14 evaluations
    eps = 1e-5
    for k, g in enumerate(grads):
        base = np.asarray(args[k], dtype=float)
        flat = base.reshape(-1)
        for i in range(flat.size):
            plus, minus = flat.copy(), flat.copy()
            plus[i] += eps
            minus[i] -= eps
            vals = [list(args) for _ in range(2)]
            vals[0][k], vals[1][k] = jnp.asarray(plus.reshape(base.shape)), jnp.asarray(minus.reshape(base.shape))
            fd = (float(loss(*vals[0])) - float(loss(*vals[1]))) / (2 * eps)
            exact = float(np.asarray(g).reshape(-1)[i])
            assert abs(fd - exact) <= FD_TOL * max(1.0, abs(exact)), (k, i, fd, exact)


def test_forward_mode_matches_reverse_mode():
    final = lambda m: integrate(gauss_legendre(BODY, 3), m, 0.2, 5).final
    gap = jax.jit(lambda m: jnp.max(jnp.abs(jax.jacfwd(final)(m) - jax.jacrev(final)(m))))  # one program
    assert float(gap(M0)) <= 1e-13


@pytest.mark.parametrize("name,order,start", [("radau-iia-2", 3, 100), ("rk4", 4, 60), ("gauss-legendre-3", 6, 12)])
def test_measured_order(name, order, start):
    fit = jaxsplit.estimate_order(runge_kutta(BODY, name), M0, STANDARD_CASE.t_end,
                                  jaxsplit.ladder(start, 8.0, 6), REFERENCE)
    assert abs(fit.order - order) <= ORDER_TOL


def test_estimate_order_fails_against_a_wrong_reference():
    wrong = REFERENCE + 1e-7  # the errors plateau at 1e-7: no longer order 4
    try:
        fit = jaxsplit.estimate_order(runge_kutta(BODY, "rk4"), M0, STANDARD_CASE.t_end,
                                      jaxsplit.ladder(60, 8.0, 6), wrong)
    except jaxsplit.InputError:  # too few points left in the fit window: also a failure to confirm order 4
        return
    assert abs(fit.order - 4) > 1.0


def test_measured_order_against_a_tight_reference_integration():
    # explicit Euler over a short horizon, reference = 200 steps of Gauss-Legendre 3
    fit = jaxsplit.estimate_order(explicit_euler(BODY), M0, 0.25, jaxsplit.ladder(2000, 8.0, 6),
                                  reference_step=gauss_legendre(BODY, 3), reference_count=200)
    assert abs(fit.order - 1) <= ORDER_TOL


def test_ruth_is_formula_2_6():
    x, h = np.array([0.3, -1.2]), 0.37
    expected = np.array([x[0] + h * x[1], -h * x[0] + (1 - h**2) * x[1]])  # in NumPy: independent of JAX
    assert np.max(np.abs(np.asarray(jax.jit(ruth())(jnp.asarray(x), h)) - expected)) <= FIELD_TOL


def test_systems_vector_fields():
    system = rigid_body_system(BODY)
    ex = example_3_1(2.0, -3.0, 1.0)
    # a user-defined system: the pendulum on (q, p)
    pendulum = jaxsplit.canonical_system(lambda x: 0.5 * x[1] ** 2 - jnp.cos(x[0]), 2)

    @jax.jit
    def fields(ms, x):  # one program (op by op: ~60)
        return jax.vmap(system.vector_field)(ms), jax.vmap(BODY.vector_field)(ms), ex.vector_field(x), \
            pendulum.vector_field(x)

    ms = _states(8)
    poisson, body, linear, canonical = map(np.asarray, fields(ms, jnp.array([0.7, 1.3])))
    assert np.max(np.abs(poisson - body)) <= FIELD_TOL
    assert np.max(np.abs(linear - np.array([-3.0 * 1.3, -2.0 * 1.3]))) <= FIELD_TOL
    assert np.max(np.abs(canonical - np.array([1.3, -np.sin(0.7)]))) <= FIELD_TOL


def test_dtype_follows_input_and_vmap_matches_loop():
    step = jax.jit(gauss_legendre(BODY, 2))
    out32 = step(M0.astype(jnp.float32), 0.1)
    assert out32.dtype == jnp.float32
    assert jax.jit(rk4(BODY))(M0.astype(jnp.float32), 0.1).dtype == jnp.float32
    xs = _states(4)
    batched = jax.jit(jax.vmap(step, in_axes=(0, None)))(xs, 0.3)
    looped = jnp.stack([step(x, 0.3) for x in xs])
    assert float(jnp.max(jnp.abs(batched - looped))) <= 1e-15


def test_bad_input():
    with pytest.raises(jaxsplit.InputError, match="unknown tableau"):
        runge_kutta(BODY, "rk5")
    with pytest.raises(jaxsplit.InputError, match=r"m must have shape \(\.\.\., 3\)"):
        gauss_legendre(BODY, 1)(jnp.ones(5), 0.1)
    with pytest.raises(jaxsplit.InputError, match="stages"):
        gauss_legendre(BODY, 0)


def test_coefficient_rk_matches_tableau_rk_and_vmaps_over_tableaus():
    from jaxsplit.classical._runge_kutta import padded_coefficients, tableaus

    names = ["rk4", "trapezoid", "gauss-legendre-3", "radau-iia-2"]  # explicit, explicit first row, implicit
    coefs = [padded_coefficients(tableaus[n], 4) for n in names]
    a_all = jnp.asarray(np.stack([c[0] for c in coefs]))
    b_all = jnp.asarray(np.stack([c[1] for c in coefs]))
    family = jax.vmap(lambda a, b: jaxsplit.runge_kutta_coefficients(BODY, a, b)(M0, 0.2))
    named = lambda: jnp.stack([runge_kutta(BODY, n)(M0, 0.2) for n in names])
    gap = jax.jit(lambda a, b: jnp.max(jnp.abs(family(a, b) - named()), axis=1))(a_all, b_all)
    assert float(jnp.max(gap)) <= 1e-15, dict(zip(names, gap.tolist()))
    # derivative with respect to a coefficient, against central differences
    a, b = (jnp.asarray(c) for c in padded_coefficients(tableaus["gauss-legendre-2"], 2))
    loss = jax.jit(lambda b0: jnp.sum(jaxsplit.runge_kutta_coefficients(BODY, a, b.at[0].set(b0))(M0, 0.3) ** 2))
    g = float(jax.grad(loss)(b[0]))
    fd = (float(loss(b[0] + 1e-6)) - float(loss(b[0] - 1e-6))) / 2e-6
    assert abs(g - fd) <= FD_TOL


def test_new_step_size_does_not_recompile():
    from jaxsplit.core._integrate import compilations

    step = gauss_legendre(BODY, 2)
    integrate(step, M0, 0.1, 7)
    before = compilations()
    for h in (0.05, 0.2, -0.1):
        integrate(step, M0, h, 7)
    assert compilations() == before


def test_system_parameters_are_traced_leaves():
    # d/dI of a GL2 integration: the HamiltonPoisson instance (inertia in a Partial) and the
    # RigidBody give the same gradient, so parameters trace through jax.grad
    def loss(inertia, make):
        return jnp.sum(gauss_legendre(make(inertia), 2)(M0, 0.3) ** 3)

    inertia = jnp.asarray(STANDARD_CASE.inertia)
    g_system = jax.jit(jax.grad(loss), static_argnums=1)(inertia, rigid_body_system)
    g_body = jax.jit(jax.grad(loss), static_argnums=1)(inertia, RigidBody)
    assert float(jnp.max(jnp.abs(g_system - g_body))) <= 1e-13
    assert float(jnp.max(jnp.abs(g_body))) > 1e-3
    with pytest.raises(jaxsplit.InputError, match="skew"):
        jaxsplit.constant_poisson_system([[0.0, 1.0], [1.0, 0.0]], lambda x: x[0])
