"""The system layer (issue 8): a user's own Lie–Poisson system from public names only,
flows as modules with traced parameters, nesting, invalid combinations, PyTree checks."""

import inspect
import re
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError

POISSON_TOL = 1e-13  # acceptance: defect of an exact Poisson map on the PyTree state
JACOBI_TOL = 1e-13  # the se(3)* structure is exactly Poisson (polynomial Π)
ORDER_TOL = 0.3  # measured orders within 0.3 of nominal
CASIMIR_TOL = 1e-13  # relative, 1000 steps
ROUNDOFF = 1e-14
T_END = 10.0
SCHEMES = ("strang", "suzuki-5", "kahan-li-6")


# ------------------------------------------------------------------ the user's system
# Acceptance 1: written with public names only, <= 30 lines (counted below).
class CarriedVector(jaxsplit.AbstractSystem):
    """A free rigid body carrying a body-frame vector v (v̇ = v × I⁻¹m): the se(3)* structure."""

    inertia: jax.Array

    def hamiltonian(self, x):
        return 0.5 * jnp.sum(x[0] ** 2 / self.inertia)

    def poisson_matrix(self, x):
        hm, hv = jaxsplit.hat(x[0]), jaxsplit.hat(x[1])
        return jnp.block([[hm, hv], [hv, jnp.zeros((3, 3), x[0].dtype)]])

    def casimirs(self):
        return {"|v|^2": lambda x: x[1] @ x[1], "<m,v>": lambda x: x[0] @ x[1]}

    def splits(self):
        return {"axes": lambda: tuple(jaxsplit.AxisRotation(k, 1 / self.inertia[k], ("momentum", "vector"))
                                      for k in range(3))}


SYSTEM = CarriedVector(jnp.array([2.0, 1.0, 2.0 / 3.0]))
X0 = (jnp.array([0.4, -0.3, 0.8]), jnp.array([0.1, 0.9, -0.4]))


def test_the_user_system_is_at_most_30_lines_of_public_names():
    source = inspect.getsource(CarriedVector)
    lines = [ln for ln in source.splitlines() if ln.strip()]
    assert len(lines) <= 30, len(lines)
    names = set(re.findall(r"jaxsplit\.(\w+)", source))
    assert names == {"AbstractSystem", "hat", "AxisRotation"}
    assert all(hasattr(jaxsplit, n) and not n.startswith("_") for n in names)


@pytest.fixture(scope="module")
def reference():
    # rolled: the same map (to 1e-14) for ~1/20 of the compilation of the unrolled Kahan-Li 8 word
    tight = jaxsplit.roll(jaxsplit.splitting(SYSTEM, "kahan-li-8"))
    return jaxsplit.integrate(tight, X0, T_END / 4000, 4000).final


@pytest.mark.parametrize("scheme", SCHEMES)
def test_user_system_integrates_poisson_and_at_its_order(scheme, reference):
    # the map with its word as data (roll): compiling the unrolled Kahan-Li 6 word (order ladder and
    # Jacobian) costs ~10 s; the unrolled composition of this system is integrated in the test below
    step = jaxsplit.roll(jaxsplit.splitting(SYSTEM, scheme))
    order = jaxsplit.schemes[scheme].order
    start = {2: 400, 4: 40, 6: 20}[order]
    fit = jaxsplit.estimate_order(step, X0, T_END, jaxsplit.ladder(start, 8.0, 6), reference)
    assert abs(fit.order - order) <= ORDER_TOL, fit
    key = jax.random.PRNGKey(1)
    states = tuple(jax.random.normal(k, (16, 3)) for k in jax.random.split(key))
    summary = jaxsplit.poisson_summary(step, SYSTEM, states, 0.3)
    assert summary.max <= POISSON_TOL and isinstance(summary.x, tuple)


def test_user_system_jacobi_and_invariants():
    states = tuple(jax.random.normal(k, (8, 3)) for k in jax.random.split(jax.random.PRNGKey(2)))
    assert jaxsplit.jacobi_summary(SYSTEM, states).max <= JACOBI_TOL
    traj = jaxsplit.integrate(jaxsplit.splitting(SYSTEM, "kahan-li-6"), X0, 0.1, 1000, save_every=10)
    errors = jax.jit(lambda traj: jaxsplit.monitor_invariants(SYSTEM, traj))(traj)  # eager: op by op
    assert set(errors) == {"energy", "|v|^2", "<m,v>"}
    assert float(errors["|v|^2"].max_relative) <= CASIMIR_TOL
    assert float(errors["<m,v>"].max_relative) <= CASIMIR_TOL
    assert 1e-12 < float(errors["energy"].max_relative) < 1e-4  # not conserved exactly, but bounded
    # the explicit Runge-Kutta methods act on the same PyTree state and are exposed
    rk = jaxsplit.rk4(SYSTEM)
    assert float(jax.jit(lambda x: jaxsplit.poisson_defect(rk, SYSTEM, x, 0.3))(X0)) > 1e-6  # eager: 2x the CPU


def test_vector_field_is_the_generic_pi_grad_h():
    field = SYSTEM.vector_field(X0)
    m, v = X0
    w = m / SYSTEM.inertia
    np.testing.assert_allclose(field[0], jnp.cross(m, w), atol=ROUNDOFF)
    np.testing.assert_allclose(field[1], jnp.cross(v, w), atol=ROUNDOFF)


# ------------------------------------------------------------------ Jacobi must-fail
def test_jacobi_check_catches_a_non_poisson_matrix():
    x = jnp.array([0.7, -0.2, 0.4])
    matrices = (jaxsplit.hat, lambda y: 2.5 * (1 + y[0] ** 2) * jaxsplit.hat(y),
                lambda y: jaxsplit.hat(jnp.stack([y[1], 0.0 * y[0], y[0]])),  # v·curl v = -x1 ≠ 0: skew, not Jacobi
                lambda y: jnp.eye(3) + jaxsplit.hat(y))  # not skew
    # one compiled call: the Jacobians taken eagerly dispatch every op on its own
    good, scaled, bad, not_skew = jax.jit(lambda y: [jaxsplit.jacobi_defect(p, y) for p in matrices])(x)
    assert float(good) <= JACOBI_TOL
    assert float(scaled) <= JACOBI_TOL
    assert float(bad) >= 0.5 * abs(float(x[0]))
    assert float(not_skew) >= 1.0


# ------------------------------------------------------------------ traced parameters
class Kick(jaxsplit.AbstractFlow):
    chi: jax.Array
    weight: float  # a Python float field: a parameter too (traced at the jit boundary)

    def __call__(self, x, t):
        return (x[0] + t * self.weight * jnp.cross(x[1], self.chi), x[1])


def _heavy_step(inertia, chi, weight):
    rotations = CarriedVector(inertia).split()
    return jaxsplit.compose(rotations + (Kick(chi, weight),), "strang")


def test_parameters_are_traced_wherever_they_sit():
    compilations = jaxsplit.core._integrate.compilations
    x0 = X0
    jaxsplit.integrate(_heavy_step(jnp.array([2.0, 1.0, 0.5]), jnp.array([0.0, 0.0, 0.3]), 1.0), x0, 0.1, 20)
    before = compilations()
    a = jaxsplit.integrate(_heavy_step(jnp.array([3.0, 1.5, 0.7]), jnp.array([0.0, 0.0, 0.3]), 1.0), x0, 0.1, 20).final
    b = jaxsplit.integrate(_heavy_step(jnp.array([3.0, 1.5, 0.7]), jnp.array([0.1, 0.0, 0.5]), 1.0), x0, 0.1, 20).final
    c = jaxsplit.integrate(_heavy_step(jnp.array([3.0, 1.5, 0.7]), jnp.array([0.1, 0.0, 0.5]), 2.5), x0, 0.05, 20).final
    assert compilations() == before  # new inertia, centre of mass, weight (a float) and h
    assert float(jnp.max(jnp.abs(a[0] - b[0]))) > 1e-3 and float(jnp.max(jnp.abs(b[0] - c[0]))) > 1e-3
    jaxsplit.integrate(_heavy_step(jnp.array([3.0, 1.5, 0.7]), jnp.array([0.1, 0.0, 0.5]), 2.5), x0, 0.05, 21)
    assert compilations() == before + 1  # the step count is static


def test_rigid_body_parameters_trace_through_grad_and_vmap():
    m0 = jnp.array([0.4, 0.0, 0.9])

    def final(inertia):
        return jaxsplit.integrate(jaxsplit.splitting(jaxsplit.RigidBody(inertia, allow_nonphysical=True), "strang", "casimir",
                                                  shift=1), m0, 0.1, 50).final

    inertias = jnp.array([[2.0, 1.0, 0.7], [3.0, 2.0, 1.0]])
    batched = jax.vmap(final)(inertias)
    for i in range(2):
        np.testing.assert_allclose(batched[i], final(inertias[i]), atol=ROUNDOFF)
    g = jax.grad(lambda i: final(i)[0])(inertias[0])
    eps = 1e-6
    fd = [(final(inertias[0].at[k].add(eps))[0] - final(inertias[0].at[k].add(-eps))[0]) / (2 * eps)
          for k in range(3)]
    np.testing.assert_allclose(g, jnp.stack(fd), rtol=1e-6, atol=1e-9)


# ------------------------------------------------------------------ nesting
def test_a_composition_is_a_flow_and_nests():
    f0, f1, f2 = jaxsplit.RigidBody([2.0, 1.0, 2 / 3], allow_nonphysical=True).split("axes")
    inner = jaxsplit.compose([f0, f1], "lie-trotter")
    assert not inner.is_group and f0.is_group
    nested = jaxsplit.compose([inner, f2], "lie-trotter")
    flat = jaxsplit.compose([f0, f1, f2], "lie-trotter")
    m = jnp.array([0.3, -0.5, 0.8])
    np.testing.assert_allclose(nested(m, 0.3), flat(m, 0.3), atol=ROUNDOFF)
    # a Strang step of (Strang(f0, f1), f2) is second order; its non-group piece is never merged
    strang = jaxsplit.compose([jaxsplit.compose([f0, f1], "strang"), f2], "strang")
    assert [p for p, _ in strang.word] == [0, 1, 0] and not strang.fsal
    body = jaxsplit.RigidBody([2.0, 1.0, 2 / 3], allow_nonphysical=True)
    ref = jaxsplit.integrate(jaxsplit.splitting(body, "kahan-li-8", "casimir"), m, 0.01, 1000).final
    fit = jaxsplit.estimate_order(strang, m, 10.0, jaxsplit.ladder(100, 8.0, 6), ref)
    assert abs(fit.order - 2) <= ORDER_TOL
    # sub-stepping a piece: Substeps(flow, n) is a flow that is not a group
    sub = jaxsplit.Substeps(jaxsplit.rk4(body), 4)
    assert not sub.is_group
    np.testing.assert_allclose(sub(m, 0.2), jaxsplit.integrate(jaxsplit.rk4(body), m, 0.05, 4).final, atol=ROUNDOFF)


# ------------------------------------------------------------------ invalid combinations
class Attitude(CarriedVector):
    """The same body, refusing the Casimir shift with a reason (as the attitude system does)."""

    refused_splits: ClassVar[dict] = {"casimir": "C = |m|²/2 is no Casimir of the larger structure"}


def test_invalid_combinations_are_clear_errors():
    with pytest.raises(InputError, match="'casimir' is not offered by Attitude: C = .* offered: axes"):
        jaxsplit.splitting(Attitude(jnp.ones(3)), "strang", "casimir")
    with pytest.raises(InputError, match="needs exactly 2 pieces"):
        jaxsplit.splitting(SYSTEM, "blanes-moan-s6-prk")
    with pytest.raises(InputError, match="not an exact one-parameter group"):
        jaxsplit.compose([jaxsplit.splitting(SYSTEM, "strang"), *SYSTEM.split()], "strang", merge_flows=True)
    with pytest.raises(InputError, match="takes no options; got shift"):
        jaxsplit.splitting(jaxsplit.RigidBody([1.0, 2.0, 3.0]), "strang", "axes", shift=1)
    with pytest.raises(InputError, match="renamed shift"):
        jaxsplit.splitting(jaxsplit.RigidBody([1.0, 2.0, 3.0]), "strang", "casimir", shift_axis=2)
    with pytest.raises(InputError, match="shift must be 0, 1, 2"):
        jaxsplit.splitting(jaxsplit.RigidBody([1.0, 2.0, 3.0]), "strang", "casimir", shift=3)
    # the free body's Casimir flows on an extended state: a clear error, not a silent wrong answer
    casimir = jaxsplit.splitting(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), "strang", "casimir")
    with pytest.raises(InputError, match="shape"):
        jaxsplit.integrate(casimir, X0, 0.1, 10)
    with pytest.raises(InputError, match=r"m must have shape \(\.\.\., 3\)"):
        jaxsplit.integrate(casimir, jnp.ones(5), 0.1, 10)


# ------------------------------------------------------------------ PyTree states
def test_integer_leaves_are_left_alone():
    step = jaxsplit.compose(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True).split("axes"), "strang")
    rotations = [jaxsplit.AxisRotation(f.axis, f.rate, ("momentum", "fixed")) for f in step.flows]
    step = jaxsplit.compose(rotations, "strang")
    x0 = (jnp.array([0.4, 0.0, 0.9]), jnp.array([7, 8], dtype=jnp.int32))
    out = jaxsplit.integrate(step, x0, 0.1, 10).final
    assert out[1].dtype == jnp.int32 and np.array_equal(out[1], x0[1])
    traj = jaxsplit.integrate(step, x0, 0.1, 10, save_every=5)
    assert traj.x[1].dtype == jnp.int32 and traj.x[0].dtype == x0[0].dtype
    defect = jax.jit(lambda x: jaxsplit.poisson_defect(step, lambda y: jaxsplit.hat(y[0]), x, 0.2))(x0)
    assert float(defect) <= POISSON_TOL
    errors = jaxsplit.invariant_errors(lambda x: x[0] @ x[0], traj)
    assert float(errors.max_relative) <= CASIMIR_TOL
    plain = jaxsplit.splitting(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), "strang")
    assert jaxsplit.integrate(plain, jnp.array([1, 0, 0]), 0.1, 3).final.dtype == jnp.result_type(float)
    with pytest.raises(InputError, match=r"tuple of 2 parts .* got an array of shape \(3,\)"):
        jaxsplit.integrate(step, jnp.array([1.0, 0, 0]), 0.1, 3)
