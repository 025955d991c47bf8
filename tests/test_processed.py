"""Processed schemes (Ψ_h = P⁻¹ ∘ K_h ∘ P): the registered coefficients give order 8 on matrices
(independently of the rigid body), a run of n steps is the step applied n times (the processor
telescopes: P once, P⁻¹ once), and the composer refuses what it cannot process exactly."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError, Scheme

NAME = "blanes-casas-murua-8"
# local error ~ C h^9: the regression slope over h = 1.2 … 0.4 (measured 8.95) within this of 9
LOCAL_SLOPE_TOL = 0.3
WORD_TOL = 1e-14  # the compiled step against its merged word, one step (measured 2.2e-16; 2.6e-15 on the matrices)
TELESCOPE_TOL = 1e-14  # advance(n) against n single steps, |m| = 1, 50 steps (measured 5.6e-16)
ROUND_OFF_NORM_TOL = 1e-13  # |m| kept over 1000 steps of 5 bodies (measured 9e-15)
GRADIENT_TOL = 1e-12  # relative, reversible against forward mode over 200 steps


def matrix_flows(a, b):
    """Two exactly solvable pieces on 5×5 matrices X: X ↦ expm(tA) X and X ↦ expm(tB) X (groups),
    each exponential from the generator's eigendecomposition (cheaper to compile than ``expm``)."""
    def piece(generator):
        lam, v = np.linalg.eig(generator)
        lam, v, v_inv = jnp.asarray(lam), jnp.asarray(v), jnp.asarray(np.linalg.inv(v))
        return jaxsplit.FunctionFlow(lambda x, t: jnp.real(v @ (jnp.exp(t * lam)[:, None] * (v_inv @ x))), group=True)
    return [piece(a), piece(b)]


def test_effective_order_8_on_random_matrices():
    """The check ``shared/reference/coefficients.md`` applies to every table: the composed word
    against expm(h(A + B)), on generators unrelated to any rigid body; without the processor the
    kernel alone is far less accurate (its order conditions are fewer). The words run rolled
    (``roll``: one compilation each); the compiled step is the word's map (next test)."""
    rng = np.random.default_rng(1)
    a, b = (0.5 * rng.standard_normal((5, 5)) for _ in range(2))
    scheme = jaxsplit.schemes[NAME]
    step = jax.jit(jaxsplit.roll(jaxsplit.compose(matrix_flows(a, b), NAME)))
    kernel = jax.jit(jaxsplit.roll(jaxsplit.compose(matrix_flows(a, b),
                                                    Scheme("kernel-only", 2, "symmetric", scheme.coefficients))))
    exact = jax.jit(lambda h: jax.scipy.linalg.expm(h * jnp.asarray(a + b)))
    hs = np.array([1.2, 0.8, 0.6, 0.4])
    eye = jnp.eye(5)
    errors = [float(jnp.max(jnp.abs(step(eye, h) - exact(h)))) for h in hs]
    kernel_errors = [float(jnp.max(jnp.abs(kernel(eye, h) - exact(h)))) for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert abs(slope - 9) <= LOCAL_SLOPE_TOL, (slope, errors)
    assert errors[-1] < 1e-3 * kernel_errors[-1], (errors, kernel_errors)


def test_a_run_is_the_step_repeated_and_the_processor_telescopes():
    body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]), allow_nonphysical=True)
    step = jaxsplit.splitting(body, NAME, "casimir")
    pre, kernel, post = step.processing
    assert pre and post == tuple((p, -w) for p, w in reversed(pre))  # P⁻¹: P's sub-flows undone
    assert step.flows_per_step == len(kernel) - 1  # a long run pays the kernel only
    assert len(step.word) > len(kernel) + len(pre)  # one step alone pays both processors
    m0 = jnp.array([0.4536, 0.0, 0.8912])
    one = jax.jit(step)  # P and P⁻¹ rolled, unmerged at their joints with K: the word's map to round-off
    assert float(jnp.max(jnp.abs(one(m0, 0.1) - jax.jit(jaxsplit.roll(step))(m0, 0.1)))) <= WORD_TOL
    repeated = m0
    for _ in range(50):
        repeated = one(repeated, 0.1)
    run = jaxsplit.integrate(step, m0, 0.1, 50).final
    assert float(jnp.max(jnp.abs(run - repeated))) <= TELESCOPE_TOL
    batch = jnp.asarray(np.random.default_rng(0).standard_normal((5, 3)))
    saved = jaxsplit.integrate(step, batch, 0.05, 1000, save_every=100)
    drift = jnp.abs(jnp.linalg.norm(saved.x, axis=-1) - jnp.linalg.norm(batch, axis=-1))
    assert float(jnp.max(drift)) <= ROUND_OFF_NORM_TOL


def test_the_processor_compiles_as_one_loop_each_way():
    """P and P⁻¹ run as data (a scan over their sub-flows, once per call), so a processed step's
    program holds a kernel per sub-flow of K only, not of P and P⁻¹ as well (compile time)."""
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]), allow_nonphysical=True), NAME, "casimir")
    _, kernel, _ = step.processing
    m0 = jnp.array([0.4536, 0.0, 0.8912])
    for program in (jax.make_jaxpr(step)(m0, 0.1), jax.make_jaxpr(lambda x: step.advance(x, 0.1, 7))(m0)):
        assert [e.primitive.name for e in program.jaxpr.eqns].count("scan") >= 2  # P and P⁻¹ as loops
        assert str(program).count("optimization_barrier") <= len(kernel) < len(step.word) / 3


def test_reversible_gradient_of_a_processed_run_equals_forward_mode():
    """The backward pass rebuilds P⁻¹ ∘ K^n ∘ P sub-flow by sub-flow; forward mode (jvp) is the
    independent reference (one compilation instead of the stored gradient's two)."""
    body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]), allow_nonphysical=True)
    step = jaxsplit.splitting(body, NAME, "casimir")
    m0, direction = jnp.array([0.4536, 0.0, 0.8912]), jnp.array([0.2, -0.7, 0.4])
    weights = jnp.array([0.3, -1.0, 2.0])

    def loss(x, adjoint="store"):
        return jnp.sum(weights * jaxsplit.integrate(step, x, 0.1, 200, adjoint=adjoint).final)

    reversible = jnp.dot(jax.grad(loss)(m0, "reversible"), direction)
    forward = jax.jvp(loss, (m0,), (direction,))[1]
    assert abs(float(reversible - forward)) <= GRADIENT_TOL * abs(float(forward))


def test_a_processor_needs_a_symmetric_scheme_and_group_flows():
    with pytest.raises(InputError, match="processor"):
        Scheme("bad", 2, "lie-adjoint", (0.5, 0.5), processor=(0.1, -0.1))
    approximate = jaxsplit.FunctionFlow(lambda x, t: x + t, group=False)
    with pytest.raises(InputError, match="processed.*piece 1"):
        jaxsplit.compose([jaxsplit.FunctionFlow(lambda x, t: x * jnp.exp(t), group=True), approximate], NAME)
    assert not jaxsplit.schemes[NAME].symmetric  # P depends on h: Ψ_{−h} ≠ Ψ_h⁻¹ in general
