"""Thermal spins (issue 33, item 3): the stochastic LLG splitting ``jaxsplit.langevin`` and the
checkerboard sampler ``jaxsplit.metropolis``, at reduced size (full size:
``benchmarks/spin_thermal.py``).

Statistical checks compare with exact thermodynamics (or with each other) within Z_MAX
standard errors, each computed from independent replicas (the spread of their means / √R).
Each test can fail: a wrong noise strength (2λT) or a wrong damping sign moves the chain's
correlation by many standard errors; an anisotropy handled differently by the two samplers
moves the square lattice's energy.

The file compiles few programs (the Langevin loop costs seconds to compile): one chain program
vmapped over (temperature, key, initial state) serves Fisher's check, the T = 0 relaxation,
reproducibility and the traced-temperature check; one Metropolis program takes the system as
an argument and serves Fisher's check and the thermal states of S(q, ω).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit

Z_MAX = 3.0  # statistical agreement: |measured − exact| <= Z_MAX standard errors
NORM_TOL = 1e-13  # |S_i| kept by rotations: round-off only
LAMBDA = 0.5
N_CHAIN, REPLICAS = 32, 8  # ring of 32: its correction to Fisher's open chain is O(u^32) < 1e-4
TEMPERATURES = (0.25, 0.5, 1.0)


def replica_stats(means):
    means = np.asarray(means)
    return float(means.mean()), float(means.std(ddof=1) / np.sqrt(len(means)))


def fisher(t):
    return 1 / np.tanh(1 / t) - t


CHAIN = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", N_CHAIN), exchange=1.0)


@jax.jit
@jax.vmap
def chain_run(t, key, s0):
    """(time-averaged ⟨S_i·S_i+1⟩ after t = 20, H at every save, max ||S_i| − 1|): h = 0.1, t = 80."""
    x = jaxsplit.integrate(jaxsplit.langevin(CHAIN, t, LAMBDA), (s0, key), 0.1, 800, save_every=5).x[0]
    corr = jnp.mean(jnp.sum(x * jnp.roll(x, -1, axis=-2), axis=-1), axis=-1)
    return jnp.mean(corr[40:]), CHAIN.hamiltonian(x), jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) - 1))


@pytest.fixture(scope="module")
def chain_batch():
    """REPLICAS per temperature, ordered starts, and two T = 0 runs from random states."""
    ts = jnp.array([t for t in TEMPERATURES for _ in range(REPLICAS)] + [0.0, 0.0])
    starts = jnp.stack([CHAIN.uniform()] * (len(ts) - 2) + [CHAIN.random_state(1), CHAIN.random_state(2)])
    keys = jax.random.split(jax.random.PRNGKey(11), len(ts))
    return (ts, keys, starts), chain_run(ts, keys, starts)


def test_heisenberg_chain_matches_fisher_at_three_temperatures(chain_batch):
    _, (corr, _, drift) = chain_batch
    corr = np.asarray(corr)[:-2].reshape(len(TEMPERATURES), REPLICAS)
    for row, t in zip(corr, TEMPERATURES):
        mean, se = replica_stats(row)
        assert abs(mean - fisher(t)) <= Z_MAX * se, (t, mean, fisher(t), se)
        assert se < 0.01  # resolved: the temperatures' u differ by > 0.2
    assert float(jnp.max(drift)) <= NORM_TOL


def test_zero_temperature_damping_lowers_the_energy(chain_batch):
    """T = 0: no noise; the exact damping pieces and the (energy-conserving to O(h²)) bond
    flows lower H monotonically towards the ferromagnet's −J per bond."""
    _, (_, energy, _) = chain_batch
    for e in np.asarray(energy)[-2:]:
        assert np.all(np.diff(e) < 1e-3 * abs(e[0]))  # monotone (up to the bond splitting's O(h²) wiggle)
        assert e[-1] < -0.9 * N_CHAIN < 0.5 * e[0]


def test_reproducible_vmappable_and_traced(chain_batch):
    (ts, keys, starts), (_, energy, _) = chain_batch
    order = np.roll(np.arange(len(ts)), 5)  # the same runs at other places in the batch
    again = chain_run(ts[order], keys[order], starts[order])
    np.testing.assert_allclose(np.asarray(again[1]), np.asarray(energy)[order], rtol=0, atol=1e-12)
    assert chain_run._cache_size() == 1  # a new order, the same program
    assert np.min(np.abs(np.diff(np.asarray(energy)[:REPLICAS, -1]))) > 1e-6  # other keys: other runs
    hotter = chain_run(ts + 0.1, keys, starts)  # temperature is traced: no recompilation
    assert chain_run._cache_size() == 1 and hotter[1].dtype == jnp.float64
    assert np.max(np.abs(np.asarray(hotter[1]) - np.asarray(energy))) > 1e-3


@jax.jit
def metropolis_runs(system, t, keys, spread):
    """Replicas (one per key) of 400 sweeps from the ordered state; the system is an argument,
    so every chain of N_CHAIN sites shares the program."""
    up = jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0]), (system.n_sites, 3))
    return jax.vmap(lambda k: jaxsplit.metropolis(system, t, up, k, 400, spread=spread))(keys)


def test_metropolis_matches_fisher_and_keeps_lengths():
    t = 0.5
    keys = jax.random.split(jax.random.PRNGKey(1), REPLICAS)
    runs = metropolis_runs(CHAIN, t, keys, 1.0)
    corr = -np.asarray(runs.energy)[:, 100:] / N_CHAIN  # H = −Σ S_i·S_{i+1}
    mean, se = replica_stats(corr.mean(axis=1))
    assert abs(mean - fisher(t)) <= Z_MAX * se, (mean, fisher(t), se)
    assert 0.2 < float(jnp.mean(runs.acceptance)) < 0.9
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(runs.final, axis=-1) - 1))) <= NORM_TOL


def test_square_lattice_energy_with_anisotropy_agrees_with_metropolis():
    """Energy per spin of the 4 × 4 ferromagnet with easy-axis anisotropy K = 0.3 at T = 1:
    sLLG against Metropolis within Z_MAX combined standard errors (√(se₁² + se₂²))."""
    square = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("square", 4), exchange=1.0, anisotropy=0.3)
    t, replicas = 1.0, 16
    keys = jax.random.split(jax.random.PRNGKey(4), 2 * replicas)
    up = square.uniform()

    def llg(key):
        x = jaxsplit.integrate(jaxsplit.langevin(square, t, LAMBDA), (up, key), 0.1, 600, save_every=5).x[0]
        return jnp.mean(square.hamiltonian(x[24:])) / square.n_sites, jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) - 1))

    means, drift = jax.jit(jax.vmap(llg))(keys[:replicas])
    e_llg, se_llg = replica_stats(means)
    mc = jax.jit(jax.vmap(lambda k: jaxsplit.metropolis(square, t, up, k, 400).energy))(keys[replicas:])
    e_mc, se_mc = replica_stats(np.asarray(mc)[:, 100:].mean(axis=1) / square.n_sites)
    assert abs(e_llg - e_mc) <= Z_MAX * np.hypot(se_llg, se_mc), (e_llg, se_llg, e_mc, se_mc)
    assert max(se_llg, se_mc) < 0.02
    assert float(jnp.max(drift)) <= NORM_TOL


@pytest.mark.parametrize(("kwargs", "needle"), [
    ({"temperature": -1.0}, "temperature must be a finite number >= 0, got -1.0"),
    ({"temperature": float("nan")}, "temperature must be a finite number >= 0, got nan"),
    ({"damping": -0.1}, "damping must be a finite number >= 0, got -0.1"),
    ({"damping": float("inf")}, "damping must be a finite number >= 0, got inf"),
])
def test_bad_input_is_one_line(kwargs, needle):
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 4))
    with pytest.raises(ValueError) as err:
        jaxsplit.langevin(chain, **({"temperature": 1.0, "damping": 0.1} | kwargs))
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_bad_input_elsewhere_is_one_line():
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 4))
    with pytest.raises(ValueError, match="temperature must be a finite number >= 0, got -2.0"):
        jaxsplit.metropolis(chain, -2.0, chain.uniform(), jax.random.PRNGKey(0), 1)
    with pytest.raises(ValueError, match="spread must be a finite number > 0, got 0.0"):
        jaxsplit.metropolis(chain, 1.0, chain.uniform(), jax.random.PRNGKey(0), 1, spread=0.0)
    with pytest.raises(ValueError, match="a Langevin state is a pair"):
        jaxsplit.integrate(jaxsplit.langevin(chain, 1.0, 0.1), chain.uniform(), 0.1, 1)
    with pytest.raises(ValueError, match="langevin acts on a spin lattice"):
        jaxsplit.langevin(jaxsplit.RigidBody([1.0, 2.0, 3.0]), 1.0, 0.1)


def test_structure_factor_from_thermal_states_peaks_on_spin_waves():
    """Metropolis states at T = 0.02 (the chain's program above), then the Poisson scheme:
    S(q, ω) peaks within 2 bins + 3 % of ω(q) = 2J(1 − cos q) + B at every q ≠ 0 (the
    classical renormalisation of the frequencies at T is of order T/J)."""
    b, h = 0.1, 0.1
    ring = jaxsplit.spin_lattice(CHAIN.lattice, exchange=1.0, field=(0.0, 0.0, b))
    states = metropolis_runs(ring, 0.02, jax.random.split(jax.random.PRNGKey(8), REPLICAS), 0.1).final[:2]
    assert metropolis_runs._cache_size() == 1  # the program of the test above: another system, the same shapes
    assert float(jnp.min(states[..., 2])) < 0.999  # thermal, not the ordered state
    poisson = jaxsplit.splitting(ring, "strang", "bonds")
    traj = jaxsplit.integrate(poisson, states, h, 1024, save_every=2).x.swapaxes(0, 1)  # a batch of two
    parts = [jaxsplit.structure_factor(traj[r], ring.lattice, 2 * h, components="xy") for r in range(2)]
    sqw = parts[0]._replace(intensity=sum(np.asarray(p.intensity) for p in parts) / 2)
    q = 2 * np.pi * np.arange(N_CHAIN) / N_CHAIN
    lsw = 2 * (1 - np.cos(q)) + b
    miss = np.abs(sqw.peak_frequencies()[1:] - lsw[1:])
    assert np.all(miss <= 2 * sqw.resolution + 0.03 * lsw[1:]), (sqw.peak_frequencies(), lsw)
