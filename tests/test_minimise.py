"""The optimiser under every fit (``explore._minimise``): Adam, then L-BFGS with a Wolfe line
search, evaluating the loss and its gradient at one place of the compiled program."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
import scipy.optimize
from jax.extend import core as jax_core

from jaxsplit.explore._minimise import minimise, minimise_flat

OPTIMUM_TOL = 1e-8  # distance to a known or SciPy-found minimum (L-BFGS converges superlinearly)
ADAM_MATCH = 1e-14  # our Adam steps against optax's own loop, relative


def rosenbrock(x):
    return jnp.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2)


def test_lbfgs_finds_the_rosenbrock_minimum():
    x0 = jnp.array([-1.2, 1.0, -1.2, 1.0])
    x, k, f = jax.jit(lambda x0: minimise_flat(rosenbrock, x0, 0, 1e-3, 500, 1e-10))(x0)
    assert np.max(np.abs(np.asarray(x) - 1)) < OPTIMUM_TOL and f < OPTIMUM_TOL**2
    ours = int(k)
    scipys = scipy.optimize.minimize(lambda y: float(rosenbrock(y)), np.asarray(x0), method="L-BFGS-B",
                                     jac=lambda y: np.asarray(jax.grad(rosenbrock)(y)), options={"gtol": 1e-10}).nit
    assert ours <= 1.5 * scipys + 5, (ours, scipys)  # as frugal as the reference implementation


def test_agrees_with_scipy_on_a_nonlinear_least_squares_problem():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((40, 5)), rng.standard_normal(40)

    def loss(x):
        r = jnp.tanh(a @ x) - 0.5 * b
        return jnp.mean(r * r)

    x, _, f = jax.jit(lambda x0: minimise_flat(loss, x0, 0, 1e-3, 200, 1e-12))(jnp.zeros(5))
    ref = scipy.optimize.minimize(lambda y: float(loss(y)), np.zeros(5), jac=lambda y: np.asarray(jax.grad(loss)(y)),
                                  method="L-BFGS-B", options={"gtol": 1e-12, "ftol": 0})
    assert np.max(np.abs(np.asarray(x) - ref.x)) < OPTIMUM_TOL and f <= ref.fun * (1 + 1e-12)


def _count(jaxpr, primitive: str) -> int:
    """Equations of ``primitive`` in a jaxpr, each sub-jaxpr counted once per place that calls it."""
    n = 0
    for eqn in jaxpr.eqns:
        n += eqn.primitive.name == primitive
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                if isinstance(sub, (jax_core.ClosedJaxpr, jax_core.Jaxpr)):
                    n += _count(getattr(sub, "jaxpr", sub), primitive)
    return n


def test_the_loss_is_evaluated_at_one_place():
    """Each place that evaluates the loss is a copy of the whole integrator for XLA to compile:
    Adam and L-BFGS together hold one (optax's Adam loop and zoom line search held three)."""
    jaxpr = jax.make_jaxpr(lambda p: minimise(lambda q: jnp.tanh(q) - 0.3, p, 3, 1e-3, 10, 1e-10))(jnp.ones(3))
    assert _count(jaxpr.jaxpr, "tanh") == 1


def test_adam_steps_are_optaxs_and_end_where_lbfgs_starts():
    x0, steps, lr = jnp.array([-1.2, 1.0, 0.3]), 7, 1e-2
    x, k, f = jax.jit(lambda x0: minimise_flat(rosenbrock, x0, steps, lr, 0, 0.0))(x0)
    opt, y = optax.adam(lr), x0
    state = opt.init(y)
    for _ in range(steps):
        updates, state = opt.update(jax.grad(rosenbrock)(y), state, y)
        y = optax.apply_updates(y, updates)
    assert int(k) == 0 and np.allclose(x, y, rtol=ADAM_MATCH, atol=0) and f == pytest.approx(float(rosenbrock(y)))


def test_steps_into_non_finite_values_are_refused_and_the_search_goes_on():
    def loss(x):  # NaN beyond x0 = 3, the minimum at (2.5, 0) just inside
        return jnp.where(x[0] > 3, jnp.nan, (x[0] - 2.5) ** 2 + x[1] ** 2)

    x, _, f = jax.jit(lambda x0: minimise_flat(loss, x0, 0, 1e-3, 100, 1e-12))(jnp.array([0.0, 1.0]))
    assert np.isfinite(f) and np.max(np.abs(np.asarray(x) - [2.5, 0.0])) < OPTIMUM_TOL


def test_at_the_minimum_it_stops_and_pytrees_come_back_in_shape():
    params = {"a": jnp.ones(2), "b": jnp.asarray(3.0)}
    fitted, k, f = jax.jit(lambda p: minimise(lambda q: jnp.concatenate([q["a"] - 1, q["b"][None] - 3]), p,
                                              0, 1e-3, 50, 0.0))(params)
    assert int(k) == 0 and float(f) == 0.0  # no descent direction at an exact minimum
    assert jax.tree_util.tree_structure(fitted) == jax.tree_util.tree_structure(params)
    assert np.array_equal(fitted["a"], params["a"]) and float(fitted["b"]) == 3.0
