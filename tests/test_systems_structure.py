"""The spinning-body systems (issue 9): attitude (m, Q) and (m, q), heavy top and gravity
gradient (m, Γ). Their Poisson matrices satisfy the Jacobi identity and give the physical
equations; every sub-flow is the exact flow of its piece; every registered scheme is a Poisson
map on them and the explicit Runge–Kutta methods are not (acceptance 2); parameters are traced,
validated, and familiar splits that do not apply are refused with a reason."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxsplit
from jaxsplit import InputError, hat
from jaxsplit.core._integrate import compilations
from jaxsplit.core._state import ravel

JACOBI_TOL = 1e-13  # polynomial structures: exact up to round-off
POISSON_TOL = 1e-13  # acceptance 2: every scheme, by jacfwd on the PyTree state
RK_FLOOR = 1e-9  # RK4 and explicit Euler at h = 0.3: far above round-off (measured 1e-5 .. 1e-1)
ODE_TOL = 1e-11  # a sub-flow against DOP853 at rtol = atol = 1e-13 over t = 2
ROUNDOFF = 1e-14

INERTIA = jnp.array([2.0, 1.0, 2.0 / 3.0])
SYMMETRIC = jnp.array([1.0, 1.0, 0.5])
CHI = jnp.array([0.1, -0.2, 0.5])
M = jnp.array([0.4, -0.3, 0.8])
GAMMA = jnp.array([0.1, 0.9, -0.4]) / np.linalg.norm([0.1, 0.9, -0.4])
Q0 = jaxsplit.rotation_matrix_about(jnp.array([0.3, -0.5, 0.8]), 1.1)
QUAT = jnp.array([0.8, 0.1, -0.3, 0.5]) / np.linalg.norm([0.8, 0.1, -0.3, 0.5])

# (label, system, state, splits): every system and every split it offers
SYSTEMS = [
    ("attitude", jaxsplit.attitude(INERTIA, allow_nonphysical=True), (M, Q0), ("axes", "spin")),
    ("attitude-quaternion", jaxsplit.attitude(INERTIA, quaternion=True, allow_nonphysical=True), (M, QUAT), ("axes", "spin")),
    ("heavy-top", jaxsplit.heavy_top(INERTIA, CHI, 1.3, allow_nonphysical=True), (M, GAMMA), ("axes",)),
    ("lagrange-top", jaxsplit.heavy_top(SYMMETRIC, jnp.array([0.0, 0.0, 0.4]), 1.3), (M, GAMMA), ("axes", "symmetric")),
    ("gravity-gradient", jaxsplit.gravity_gradient(INERTIA, 0.7, allow_nonphysical=True), (M, GAMMA), ("axes",)),
    ("gravity-gradient-symmetric", jaxsplit.gravity_gradient(SYMMETRIC, 0.7), (M, GAMMA), ("axes", "symmetric")),
]
IDS = [s[0] for s in SYSTEMS]


def _random_states(system, x0, n, seed):
    """n states of x0's layout: a random unit m, a random unit Γ / rotation / unit quaternion."""
    keys = jax.random.split(jax.random.PRNGKey(seed), 2)
    m = jax.random.normal(keys[0], (n, 3))
    m = m / jnp.linalg.norm(m, axis=1, keepdims=True)
    if isinstance(system, jaxsplit.Attitude) and not system.quaternion:
        axes = jax.random.normal(keys[1], (n, 3))
        return m, jax.vmap(jaxsplit.rotation_matrix_about)(axes, jnp.linalg.norm(axes, axis=1))
    size = 4 if isinstance(system, jaxsplit.Attitude) else 3
    v = jax.random.normal(keys[1], (n, size))
    return m, v / jnp.linalg.norm(v, axis=1, keepdims=True)


# ------------------------------------------------------------------ the structure
@pytest.mark.parametrize("label, system, x0, splits", SYSTEMS, ids=IDS)
def test_poisson_matrix_satisfies_jacobi(label, system, x0, splits):
    states = _random_states(system, x0, 6, 1)
    assert jaxsplit.jacobi_summary(system, states).max <= JACOBI_TOL


def test_jacobi_check_catches_wrong_couplings():
    """Must-fail: the se(3)* coupling with the wrong sign, and the quaternion kinematics of the
    spatial frame (q̇ = ½ (0, ω) ⊗ q) paired with body momenta, are not Poisson structures."""
    wrong_sign = lambda y: jnp.block([[hat(y[0]), -hat(y[1])], [-hat(y[1]), jnp.zeros((3, 3))]])

    def spatial(y):
        w, v = y[1][0], y[1][1:]
        b = 0.5 * jnp.concatenate([-v[None, :], w * jnp.eye(3) - hat(v)], axis=0)  # (0, ω) ⊗ q
        return jnp.block([[hat(y[0]), -b.T], [b, jnp.zeros((4, 4))]])

    # one compiled call: the Jacobian taken eagerly dispatches every op on its own (~7x the CPU)
    defects = jax.jit(lambda x, y: (jaxsplit.jacobi_defect(wrong_sign, x), jaxsplit.jacobi_defect(spatial, y)))
    wrong, spatial_frame = defects((M, GAMMA), (M, QUAT))
    assert float(wrong) > 0.1
    assert float(spatial_frame) > 0.1


def test_vector_fields_are_the_physical_equations():
    """Π∇H (generic, jax.grad) against the equations written out by hand."""
    w = 1 / INERTIA
    omega = w * M
    attitude = jaxsplit.attitude(INERTIA, allow_nonphysical=True).vector_field((M, Q0))
    np.testing.assert_allclose(attitude[0], jnp.cross(M, omega), atol=ROUNDOFF)
    np.testing.assert_allclose(attitude[1], Q0 @ hat(omega), atol=ROUNDOFF)
    quaternion = jaxsplit.attitude(INERTIA, quaternion=True, allow_nonphysical=True).vector_field((M, QUAT))
    np.testing.assert_allclose(quaternion[1], 0.5 * jaxsplit.quaternion_multiply(QUAT, jnp.concatenate(
        [jnp.zeros(1), omega])), atol=ROUNDOFF)
    top = jaxsplit.heavy_top(INERTIA, CHI, 1.3, allow_nonphysical=True).vector_field((M, GAMMA))
    np.testing.assert_allclose(top[0], jnp.cross(M, omega) + 1.3 * jnp.cross(GAMMA, CHI), atol=ROUNDOFF)
    np.testing.assert_allclose(top[1], jnp.cross(GAMMA, omega), atol=ROUNDOFF)
    satellite = jaxsplit.gravity_gradient(INERTIA, 0.7, allow_nonphysical=True).vector_field((M, GAMMA))
    torque = 3 * 0.7**2 * jnp.cross(GAMMA, INERTIA * GAMMA)  # the gravity-gradient torque
    np.testing.assert_allclose(satellite[0], jnp.cross(M, omega) + torque, atol=ROUNDOFF)


# ------------------------------------------------------------------ exact sub-flows
def _pieces(system, split):
    """The Hamiltonian of each piece of a split, written independently of the library."""
    w = 1 / system.inertia
    rotation = [lambda x, k=k: 0.5 * w[k] * x[0][k] ** 2 for k in range(3)]
    potential = (lambda x: system.potential(x[1])) if hasattr(system, "potential") else None
    if split == "axes":
        return rotation + ([potential] if potential else [])
    if split == "spin":  # shift 1: (w0 − w1) m0²/2 + w1 |m|²/2, then (w2 − w1) m2²/2
        return [lambda x: 0.5 * (w[0] - w[1]) * x[0][0] ** 2 + 0.5 * w[1] * x[0] @ x[0],
                lambda x: 0.5 * (w[2] - w[1]) * x[0][2] ** 2]
    if split == "symmetric":  # the kinetic energy, then V
        return [lambda x: 0.5 * jnp.sum(w * x[0] ** 2), potential]
    raise AssertionError(split)


@pytest.mark.parametrize("label, system, x0, splits", SYSTEMS, ids=IDS)
def test_every_sub_flow_is_the_exact_flow_of_its_piece(label, system, x0, splits):
    flat0, unravel = ravel(x0)
    for split in splits:
        flows = system.split(split, **({"shift": 1} if split == "spin" else {}))
        for flow, piece in zip(flows, _pieces(system, split), strict=True):
            field = jax.jit(lambda v, piece=piece: system.poisson_matrix(unravel(v)) @ jax.grad(
                lambda u: piece(unravel(u)))(v))
            ref = solve_ivp(lambda t, v, f=field: np.asarray(f(jnp.asarray(v))), (0, 2.0), np.asarray(flat0),
                            method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
            np.testing.assert_allclose(ravel(flow(x0, 2.0))[0], ref, atol=ODE_TOL, err_msg=f"{label} {split}")
            assert flow.is_group  # so the composer may merge adjacent sub-flows


# ------------------------------------------------------------------ every scheme is Poisson
# every system with its richest split: the two-piece one where it exists (PRK schemes apply)
POISSON_CASES = [(label, system, x0, splits[-1]) for label, system, x0, splits in SYSTEMS
                 if label != "gravity-gradient-symmetric"]  # its flows: the Lagrange top's and the satellite's


@pytest.mark.parametrize("label, system, x0, split", POISSON_CASES, ids=[c[0] for c in POISSON_CASES])
def test_every_scheme_is_poisson_and_runge_kutta_is_not(label, system, x0, split):
    states = _random_states(system, x0, 4, 2)
    # sub-steps |w| h in [1e-3, 1]: beyond, DΦ of the triple jumps (|w| up to 5) reaches 1e4-1e26
    # and the defect is round-off times |DΦ|², measuring nothing about the map
    sub_steps = jnp.array([1e-3, 0.05, 0.3, 1.0])

    @jax.jit  # one compilation for every scheme of a split: the word is data (roll)
    def worst(step, steps):
        return jax.vmap(lambda x, h: jaxsplit.poisson_defect(step, system, x, h))(states, steps).max()

    comps = []
    for name in jaxsplit.schemes:
        try:
            comps.append(jaxsplit.splitting(system, name, split))
        except InputError:  # partitioned schemes need two pieces
            assert jaxsplit.schemes[name].form == "partitioned" and len(system.split(split)) != 2
    length = max(len(c.word) for c in comps)
    for comp in comps:
        largest = max(1.0, max(abs(w) for _, w in comp.word))
        defect = float(worst(jaxsplit.roll(comp, length), sub_steps / largest))
        assert defect <= POISSON_TOL, (label, split, comp.scheme.name, defect)
    assert len(comps) >= len(jaxsplit.schemes) - 2
    for method in (jaxsplit.rk4, jaxsplit.explicit_euler):  # compiled: RK4's Jacobian op by op took ~6 s CPU
        defect = jax.jit(lambda x, method=method: jaxsplit.poisson_defect(method(system), system, x, 0.3))(x0)
        assert float(defect) > RK_FLOOR, (label, method)


# ------------------------------------------------------------------ parameters
def test_parameters_are_traced():
    """A new centre of mass, weight, inertia, rate or step reuses the compiled loop."""
    def run(system, h=0.1):
        return jaxsplit.integrate(jaxsplit.splitting(system, "strang"), (M, GAMMA), h, 20).final

    first = run(jaxsplit.heavy_top(INERTIA, CHI, 1.3, allow_nonphysical=True))
    before = compilations()
    other = run(jaxsplit.heavy_top(INERTIA * 1.2, CHI[::-1], 0.4, allow_nonphysical=True), 0.07)
    assert compilations() == before
    assert float(jnp.max(jnp.abs(first[0] - other[0]))) > 1e-3
    run(jaxsplit.gravity_gradient(INERTIA, 0.7, allow_nonphysical=True))
    before = compilations()
    run(jaxsplit.gravity_gradient(INERTIA * 0.9, 1.1, allow_nonphysical=True))
    assert compilations() == before


@pytest.mark.parametrize("build, message", [
    (lambda: jaxsplit.heavy_top([1.0, -1.0, 2.0], CHI), "inertia must be positive"),
    (lambda: jaxsplit.heavy_top([1.0, 0.0, 2.0], CHI), "inertia must be positive"),
    (lambda: jaxsplit.heavy_top(INERTIA, [0.0, np.nan, 1.0], allow_nonphysical=True), "center_of_mass must be finite"),
    (lambda: jaxsplit.heavy_top(INERTIA, [0.0, np.inf, 1.0], allow_nonphysical=True), "center_of_mass must be finite"),
    (lambda: jaxsplit.heavy_top(INERTIA, [0.0, 1.0], allow_nonphysical=True), "center_of_mass must have 3 components"),
    (lambda: jaxsplit.heavy_top(INERTIA, CHI, -1.0, allow_nonphysical=True), "weight must be finite and >= 0"),
    (lambda: jaxsplit.heavy_top(INERTIA, CHI, np.nan, allow_nonphysical=True), "weight must be finite and >= 0"),
    (lambda: jaxsplit.gravity_gradient(INERTIA, -0.1, allow_nonphysical=True), "rate must be finite and >= 0"),
    (lambda: jaxsplit.gravity_gradient([1.0, 2.0, np.inf], 0.1), "inertia must be finite"),
    (lambda: jaxsplit.attitude([1.0, 2.0]), "3 components"),
    (lambda: jaxsplit.attitude(INERTIA, quaternion="yes", allow_nonphysical=True), "quaternion must be True or False"),
    (lambda: jaxsplit.heavy_top([1.0, np.nan, 2.0], CHI), "inertia must be finite"),
    (lambda: jaxsplit.gravity_gradient(INERTIA, np.inf, allow_nonphysical=True), "rate must be finite and >= 0"),
    (lambda: jaxsplit.heavy_top(INERTIA, "up", allow_nonphysical=True), "center_of_mass must be numeric"),
])
def test_bad_parameters_are_one_line_errors(build, message):
    with pytest.raises(InputError, match=message) as info:
        build()
    assert "\n" not in str(info.value)


GOOD_STATES = [  # (system, state): every one passes check_state
    (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), (M, GAMMA)),
    (jaxsplit.gravity_gradient(INERTIA, 0.7, allow_nonphysical=True), (jnp.stack([M, -M]), jnp.stack([GAMMA, -GAMMA]))),  # a batch
    (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), (M.astype(jnp.float32), (GAMMA * (1 + 1e-4)).astype(jnp.float32))),
    (jaxsplit.attitude(INERTIA, allow_nonphysical=True), (M, Q0)),
    (jaxsplit.attitude(INERTIA, quaternion=True, allow_nonphysical=True), (M, QUAT)),
]
BAD_STATES = [  # (system, state, message)
    (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), (M, 2 * GAMMA), r"Γ must be a unit vector .* got \|Γ\| = \[2.0\]"),
    (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), (M, GAMMA * (1 + 1e-4)), "Γ must be a unit vector"),  # float64: √ε = 1.5e-8
    (jaxsplit.gravity_gradient(INERTIA, 0.7, allow_nonphysical=True), (M.at[1].set(np.nan), GAMMA), "must be finite, got \\[nan\\]"),
    (jaxsplit.attitude(INERTIA, allow_nonphysical=True), (M, 1.01 * Q0), "Q must be orthogonal"),
    (jaxsplit.attitude(INERTIA, allow_nonphysical=True), (M, Q0 * jnp.array([1.0, 1.0, -1.0])), "Q must be a rotation, not a reflection"),
    (jaxsplit.attitude(INERTIA, quaternion=True, allow_nonphysical=True), (M, 1.1 * QUAT), "q must be a unit quaternion"),
    (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), M, r"tuple \(m, Γ\)"),
]


@pytest.mark.parametrize("system, state", GOOD_STATES)
def test_good_states_pass_the_state_check(system, state):
    assert system.check_state(state) is state


@pytest.mark.parametrize("system, state, message", BAD_STATES)
def test_bad_states_are_one_line_errors(system, state, message):
    with pytest.raises(InputError, match=message) as info:
        system.check_state(state)
    assert "\n" not in str(info.value)


def test_exact_solution_checks_the_attitude():
    with pytest.raises(InputError, match="Q must be a rotation"):
        jaxsplit.exact_solution(jaxsplit.RigidBody(INERTIA, allow_nonphysical=True), (M, -Q0), 1.0)


def test_zero_weight_is_a_free_body_carrying_the_vertical():
    """weight = 0 is legal: m follows the free body's exact solution, Γ the transported vertical."""
    top = jaxsplit.heavy_top(INERTIA, CHI, 0.0, allow_nonphysical=True)
    x = jaxsplit.integrate(jaxsplit.roll(jaxsplit.splitting(top, "kahan-li-8")), (M, Q0[2]), 0.01, 500).final
    m, q = jaxsplit.exact_solution(top, (M, Q0), 5.0)
    np.testing.assert_allclose(x[0], m, atol=1e-12)
    np.testing.assert_allclose(x[1], q[2], atol=1e-12)  # Γ = Qᵀ e_3: the third row of Q


def test_refused_and_conditional_splits():
    for system, state in [(jaxsplit.attitude(INERTIA, allow_nonphysical=True), (M, Q0)), (jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), (M, GAMMA)),
                          (jaxsplit.gravity_gradient(INERTIA, 0.5, allow_nonphysical=True), (M, GAMMA))]:
        with pytest.raises(InputError, match="'casimir' is not offered by .*no Casimir"):
            jaxsplit.splitting(system, "strang", "casimir")
    with pytest.raises(InputError, match="needs I1 = I2"):
        jaxsplit.splitting(jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), "strang", "symmetric")
    with pytest.raises(InputError, match="needs exactly 2 pieces"):
        jaxsplit.splitting(jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True), "blanes-moan-s6-prk")
    with pytest.raises(InputError, match="shift must be 0, 1, 2"):
        jaxsplit.splitting(jaxsplit.attitude(INERTIA, allow_nonphysical=True), "strang", "spin", shift=5)
    assert jaxsplit.attitude(INERTIA, allow_nonphysical=True).resolve_split("spin") == ("spin", {"shift": 1})
    with pytest.raises(InputError, match=r"the attitude part must have shape \(\.\.\., 3, 3\)"):
        jaxsplit.integrate(jaxsplit.splitting(jaxsplit.attitude(INERTIA, allow_nonphysical=True), "strang"), (M, QUAT), 0.1, 2)
    with pytest.raises(InputError, match=r"tuple \(m, Γ\)"):
        jaxsplit.heavy_top(INERTIA, CHI, allow_nonphysical=True).hamiltonian(M)
