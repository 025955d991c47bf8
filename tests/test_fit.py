"""fit_inertia (acceptance 1), identifiability, long-horizon gradients (acceptance 2), CLI."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError
from jaxsplit.cli import main

RATIO_RTOL = 0.01  # acceptance 1: ratios within 1%
SIGMA_MULTIPLE = 5.0  # recovered ratios within 5 reported standard deviations
NOISE_RTOL = 0.2  # estimated noise level vs the true one
NULL_ALIGNMENT = 0.999  # GN null vector vs the predicted Casimir-shift direction
NULL_RATIO = 1e-10  # smallest / largest GN eigenvalue in full log-inertia coordinates
GRAD_RTOL = 1e-6  # acceptance 2: gradient through 1e4 steps vs central differences
CHECKPOINT_MATCH = 1e-10  # checkpointed vs plain (relative): round-off of 1e4 steps, merged differently
FD_EPS = 1e-6

TRUE_INERTIA = np.array([1.3, 2.1, 2.9])
NOISE = 1e-3

# The three fits of ``observations`` share one compiled optimiser (same model and data shape):
# one worker runs them, so the module fixture and the compilation are paid once, not per worker.
SHARED_FIT = pytest.mark.xdist_group("fit-inertia-observations")


@pytest.fixture(scope="module")
def observations():
    rng = np.random.default_rng(11)
    m0 = rng.standard_normal(3)
    m0 /= np.linalg.norm(m0)
    t = np.linspace(0.0, 20.0, 200)
    return t, jaxsplit.simulate_observations(TRUE_INERTIA, m0, t, NOISE, seed=12), m0


@SHARED_FIT
def test_recovers_ratios_within_one_percent(observations):
    """How fast: ``benchmarks/fit_inertia.py`` (a wall-clock limit here would fail on a loaded machine)."""
    t, m, m0 = observations
    energy = 0.5 * np.sum(m0**2 / TRUE_INERTIA)
    res = jaxsplit.fit_inertia(t, m, energy=energy, energy_sigma=1e-3 * energy)
    truth = TRUE_INERTIA[1:] / TRUE_INERTIA[0]
    err = res.inertia_ratios / truth - 1
    assert np.all(np.abs(err) < RATIO_RTOL), err
    assert np.all(np.abs(res.inertia_ratios - truth) < SIGMA_MULTIPLE * res.ratio_std)
    assert abs(res.noise_sigma / NOISE - 1) < NOISE_RTOL
    w = 1 / TRUE_INERTIA
    d_true = (w - w[2])[:2]
    assert np.all(np.abs(res.inverse_differences - d_true) < SIGMA_MULTIPLE * res.inverse_differences_std)
    # the unidentifiable direction: a null vector of the Gauss-Newton Hessian, along ∝ I
    assert res.null_alignment > NULL_ALIGNMENT
    assert res.hessian_eigenvalues[0] / res.hessian_eigenvalues[-1] < NULL_RATIO
    assert res.iterations > 0 and res.loss < 2 * NOISE**2


@SHARED_FIT
def test_without_gauge_information_the_ratios_are_an_assumption(observations):
    t, m, _ = observations
    res = jaxsplit.fit_inertia(t, m)
    assert "ASSUMED" in res.gauge and res.inertia[0] == pytest.approx(1.0, rel=1e-12)
    truth = TRUE_INERTIA[1:] / TRUE_INERTIA[0]
    assert np.any(np.abs(res.inertia_ratios / truth - 1) > RATIO_RTOL)  # honest: not identifiable
    lo, hi = res.ratio_range[:, 0], res.ratio_range[:, 1]
    assert np.all((lo <= truth) & (truth <= hi))  # yet the truth lies in the range m(t) allows


def test_long_horizon_gradient_matches_finite_differences():
    n_steps, h = 10_000, 0.01
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)
    target = jnp.asarray(jaxsplit.STANDARD_CASE.reference)

    def loss(log_inertia, checkpointed=True):
        step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.exp(log_inertia), allow_nonphysical=True), "strang")
        final = (jaxsplit.integrate_checkpointed(step, m0, h, n_steps) if checkpointed
                 else jaxsplit.integrate(step, m0, h, n_steps).final)
        return jnp.sum((final - target) ** 2)

    x = jnp.log(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    value_and_grad = jax.jit(jax.value_and_grad(loss))  # one compilation: the gradient and the 6 values
    grad = np.asarray(value_and_grad(x)[1])
    plain = np.asarray(jax.jit(jax.grad(lambda y: loss(y, False)))(x))
    assert np.max(np.abs(grad - plain)) < CHECKPOINT_MATCH * np.max(np.abs(grad))
    value = lambda y: float(value_and_grad(y)[0])
    eye = np.eye(3)
    fd = np.array([(value(x + FD_EPS * e) - value(x - FD_EPS * e)) / (2 * FD_EPS) for e in eye])
    assert np.max(np.abs(grad - fd)) < GRAD_RTOL * np.max(np.abs(grad))
    # forward values are those of integrate
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.exp(x), allow_nonphysical=True), "strang")
    a = jax.jit(lambda y: jaxsplit.integrate_checkpointed(step, y, h, 1234, block=100))(m0)  # not jitted itself
    b = jaxsplit.integrate(step, m0, h, 1234).final
    assert np.max(np.abs(np.asarray(a) - np.asarray(b))) < CHECKPOINT_MATCH


def test_checkpointed_gradient_memory_grows_sublinearly():
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)

    def temp_bytes(n, checkpointed):
        def loss(log_inertia):
            step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.exp(log_inertia), allow_nonphysical=True), "strang")
            final = (jaxsplit.integrate_checkpointed(step, m0, 0.01, n) if checkpointed
                     else jaxsplit.integrate(step, m0, 0.01, n).final)
            return jnp.sum(final ** 2)

        x = jnp.zeros(3)
        return jax.jit(jax.grad(loss)).lower(x).compile().memory_analysis().temp_size_in_bytes

    small, large = 4_096, 65_536  # 16x the steps (perfect squares: whole blocks)
    ckpt_large = temp_bytes(large, True)  # compiled once, used by both checks
    assert ckpt_large / temp_bytes(small, True) < 6  # blocks of sqrt(n): ~sqrt(16) = 4, far from a linear law's 16
    # the stored adjoint keeps one state in KEEP_EVERY: linear in n (16x the steps, > 8x the memory), and
    # at 65,536 steps above the checkpointed run's sqrt-sized blocks
    plain_large = temp_bytes(large, False)
    assert plain_large > 8 * temp_bytes(small, False) and plain_large > 2 * ckpt_large


@SHARED_FIT
def test_cli_fit_json(tmp_path, capsys, observations):
    t, m, _ = observations
    path = tmp_path / "obs.npz"
    np.savez(path, t=t, m=m, inertia1=TRUE_INERTIA[0])
    assert main(["fit", "--data", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"inertia_ratios", "loss", "iterations", "gauge"} <= set(out)
    truth = TRUE_INERTIA[1:] / TRUE_INERTIA[0]
    assert np.all(np.abs(np.array(out["inertia_ratios"]) / truth - 1) < RATIO_RTOL)
    assert "known I1" in out["gauge"]


@pytest.mark.parametrize("content, match", [
    ({"t": np.arange(5.0)}, "missing"),
    ({"t": np.arange(5.0), "m": np.zeros((4, 3))}, "shape"),
    ({"t": np.arange(5.0), "m": np.array(["a"] * 15).reshape(5, 3)}, "numeric"),
])
def test_cli_malformed_data_is_one_line(tmp_path, capsys, content, match):
    path = tmp_path / "bad.npz"
    np.savez(path, **content)
    assert main(["fit", "--data", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and match in err


def test_bad_observations():
    t = np.linspace(0, 1, 10)
    m = np.ones((10, 3))
    with pytest.raises(InputError, match="increasing"):
        jaxsplit.fit_inertia(t[::-1], m)
    with pytest.raises(InputError, match="shape"):
        jaxsplit.fit_inertia(t, m[:5])
    with pytest.raises(InputError, match="finite"):
        jaxsplit.fit_inertia(t, np.full((10, 3), np.nan))
    with pytest.raises(InputError, match="not both"):
        jaxsplit.fit_inertia(t, m, energy=1.0, inertia1=1.0)
