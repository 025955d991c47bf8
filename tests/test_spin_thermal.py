"""Thermal spins (issue 33, item 3): the stochastic LLG splitting ``jaxsplit.langevin`` and the
checkerboard sampler ``jaxsplit.metropolis``, at reduced size (full size:
``benchmarks/spin_thermal.py``).

Statistical checks compare with exact thermodynamics within Z_MAX standard errors, each
standard error computed from independent replicas (the spread of their means / √R). Each test
can fail: a wrong noise strength (2λT) moves the single-spin magnetisation by many standard
errors, a wrong sign of the damping sends the chain's correlation to the wrong side of Fisher's.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit

Z_MAX = 3.0  # statistical agreement: |measured − exact| <= Z_MAX standard errors
NORM_TOL = 1e-13  # |S_i| kept by rotations: round-off only
LAMBDA = 0.5


def replica_stats(means):
    means = np.asarray(means)
    return float(means.mean()), float(means.std(ddof=1) / np.sqrt(len(means)))


def test_one_spin_in_a_field_samples_the_langevin_function():
    """⟨S·B̂⟩ = coth(β|B|) − 1/(β|B|) for one unit spin; 256 replicas in one batch."""
    one = jaxsplit.spin_lattice(jaxsplit.lattices.graph(1, np.zeros((0, 2), int)), field=(0.0, 0.0, 1.0))
    t, replicas = 0.5, 128
    step = jaxsplit.langevin(one, t, LAMBDA)
    s0 = jnp.tile(one.uniform((1.0, 0.0, 0.0))[None], (replicas, 1, 1))
    x = jaxsplit.integrate(step, (s0, jax.random.PRNGKey(3)), 0.1, 800, save_every=5).x[0]
    mean, se = replica_stats(np.asarray(x[40:, :, 0, 2]).mean(axis=0))
    exact = 1 / np.tanh(1 / t) - t
    assert abs(mean - exact) <= Z_MAX * se, (mean, exact, se)
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) - 1))) <= NORM_TOL


def test_heisenberg_chain_matches_fisher_at_three_temperatures():
    """⟨S_i·S_{i+1}⟩ = coth(βJ) − 1/(βJ) (Fisher 1964) on a ring of 32 (ring correction
    O(u^32) < 1e-4), T = 0.25, 0.5, 1: one compiled program vmapped over temperatures and keys."""
    n, replicas, h, steps, every = 32, 8, 0.1, 1000, 5
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", n), exchange=1.0)
    temperatures = jnp.array([0.25, 0.5, 1.0])
    up = chain.uniform()

    def run(t, key):
        sol = jaxsplit.integrate(jaxsplit.langevin(chain, t, LAMBDA), (up, key), h, steps, save_every=every)
        x = sol.x[0]
        corr = jnp.mean(jnp.sum(x * jnp.roll(x, -1, axis=-2), axis=-1), axis=-1)
        return jnp.mean(corr[40:]), jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) - 1))

    ts = jnp.repeat(temperatures, replicas)
    keys = jax.random.split(jax.random.PRNGKey(11), len(ts))
    means, drift = jax.jit(jax.vmap(run))(ts, keys)
    means = np.asarray(means).reshape(3, replicas)
    for k, t in enumerate(np.asarray(temperatures)):
        mean, se = replica_stats(means[k])
        exact = 1 / np.tanh(1 / t) - t
        assert abs(mean - exact) <= Z_MAX * se, (t, mean, exact, se)
        assert se < 0.01  # the runs are long enough to resolve the temperatures apart
    assert float(jnp.max(drift)) <= NORM_TOL


def test_metropolis_matches_fisher_and_keeps_lengths():
    n, replicas, sweeps, t = 32, 8, 600, 0.5
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", n), exchange=1.0)
    up = chain.uniform()
    runs = jax.jit(jax.vmap(lambda k: jaxsplit.metropolis(chain, t, up, k, sweeps)))(
        jax.random.split(jax.random.PRNGKey(1), replicas))
    corr = -np.asarray(runs.energy)[:, 100:] / n  # H = −Σ S_i·S_{i+1}
    mean, se = replica_stats(corr.mean(axis=1))
    exact = 1 / np.tanh(1 / t) - t
    assert abs(mean - exact) <= Z_MAX * se, (mean, exact, se)
    assert 0.2 < float(jnp.mean(runs.acceptance)) < 0.9
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(runs.final, axis=-1) - 1))) <= NORM_TOL


def test_square_lattice_energy_agrees_with_metropolis():
    """Energy per spin of the 6 × 6 ferromagnet at T = 1: sLLG against Metropolis, within
    Z_MAX combined standard errors (√(se₁² + se₂²))."""
    square = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("square", 6), exchange=1.0)
    t, replicas = 1.0, 8
    keys = jax.random.split(jax.random.PRNGKey(4), 2 * replicas)
    up = square.uniform()

    def llg(key):
        x = jaxsplit.integrate(jaxsplit.langevin(square, t, LAMBDA), (up, key), 0.1, 800,
                               save_every=5).x[0]
        return jnp.mean(square.hamiltonian(x[30:])) / square.n_sites

    e_llg, se_llg = replica_stats(jax.jit(jax.vmap(llg))(keys[:replicas]))
    mc = jax.jit(jax.vmap(lambda k: jaxsplit.metropolis(square, t, up, k, 600).energy))(keys[replicas:])
    e_mc, se_mc = replica_stats(np.asarray(mc)[:, 150:].mean(axis=1) / square.n_sites)
    assert abs(e_llg - e_mc) <= Z_MAX * np.hypot(se_llg, se_mc), (e_llg, se_llg, e_mc, se_mc)


def test_zero_temperature_damping_relaxes_to_the_ground_state():
    """T = 0: no noise, the exact damping pieces lower H to the ferromagnet's −J per bond."""
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 8), exchange=1.0, anisotropy=0.3)
    s0 = chain.random_state(seed=2)
    x = jaxsplit.integrate(jaxsplit.langevin(chain, 0.0, 1.0), (s0, jax.random.PRNGKey(0)), 0.1, 200,
                           save_every=20).x[0]
    energy = np.asarray(chain.hamiltonian(x))
    assert np.all(np.diff(energy) < 1e-12)  # monotone, up to round-off
    assert abs(energy[-1] - (-8.0 - 8 * 0.3)) < 1e-6  # all aligned along the easy axis


def test_reproducible_vmappable_and_jittable():
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 8), exchange=1.0, field=(0.0, 0.2, 0.1))
    step = jaxsplit.langevin(chain, 0.7, 0.3)
    s0 = chain.random_state(seed=1)
    keys = jax.random.split(jax.random.PRNGKey(5), 3)

    @jax.jit
    def final(key):
        return jaxsplit.integrate(step, (s0, key), 0.05, 20).final[0]

    direct = np.stack([np.asarray(final(k)) for k in keys])
    np.testing.assert_array_equal(np.asarray(final(keys[0])), direct[0])  # the same key: the same run
    alone = np.asarray(jaxsplit.integrate(step, (s0, keys[0]), 0.05, 20).final[0])  # not under the user's jit
    np.testing.assert_allclose(alone, direct[0], rtol=0, atol=1e-13)
    assert np.max(np.abs(direct[1] - direct[0])) > 1e-3  # another key: another run
    batched = np.asarray(jax.jit(jax.vmap(final))(keys))
    np.testing.assert_allclose(batched, direct, rtol=0, atol=1e-13)
    assert batched.dtype == np.float64
    # temperature and damping are traced: a new value reuses the compiled program
    traced = jax.jit(lambda t, k: jaxsplit.integrate(jaxsplit.langevin(chain, t, 0.3), (s0, k), 0.05, 5).final[0])
    traced(0.7, keys[0])
    before = traced._cache_size()
    traced(1.3, keys[0])
    assert traced._cache_size() == before


@pytest.mark.parametrize(("kwargs", "needle"), [
    ({"temperature": -1.0}, "temperature must be a finite number >= 0, got -1.0"),
    ({"temperature": float("nan")}, "temperature must be a finite number >= 0, got nan"),
    ({"damping": -0.1}, "damping must be a finite number >= 0, got -0.1"),
    ({"damping": float("inf")}, "damping must be a finite number >= 0, got inf"),
])
def test_bad_input_is_one_line(kwargs, needle):
    chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 4))
    with pytest.raises(ValueError, match=None) as err:
        jaxsplit.langevin(chain, **({"temperature": 1.0, "damping": 0.1} | kwargs))
    assert needle in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ValueError, match="temperature must be"):
        jaxsplit.metropolis(chain, -2.0, chain.uniform(), jax.random.PRNGKey(0), 1)
    with pytest.raises(ValueError, match="a Langevin state is a pair"):
        jaxsplit.integrate(jaxsplit.langevin(chain, 1.0, 0.1), chain.uniform(), 0.1, 1)


def test_structure_factor_from_thermal_states_peaks_on_spin_waves():
    """Metropolis states at T = 0.02, then the Poisson scheme: S(q, ω) peaks within 2 bins + 3 %
    of ω(q) = 2J(1 − cos q) + B at every q ≠ 0 (classical renormalisation at T: ~T/J)."""
    n, b, h = 16, 0.1, 0.1
    ring = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", n), exchange=1.0, field=(0.0, 0.0, b))
    up = ring.uniform()
    states = jax.vmap(lambda k: jaxsplit.metropolis(ring, 0.02, up, k, 300).final)(
        jax.random.split(jax.random.PRNGKey(8), 2))
    assert float(jnp.min(states[..., 2])) < 0.999  # thermal, not the ordered state
    poisson = jaxsplit.splitting(ring, "strang", "bonds")
    traj = jax.vmap(lambda s: jaxsplit.integrate(poisson, s, h, 1024, save_every=2).x)(states)
    parts = [jaxsplit.structure_factor(traj[r], ring.lattice, 2 * h, components="xy") for r in range(2)]
    sqw = parts[0]._replace(intensity=sum(np.asarray(p.intensity) for p in parts) / 2)
    q = 2 * np.pi * np.arange(n) / n
    lsw = 2 * (1 - np.cos(q)) + b
    miss = np.abs(sqw.peak_frequencies()[1:] - lsw[1:])
    assert np.all(miss <= 2 * sqw.resolution + 0.03 * lsw[1:]), (sqw.peak_frequencies(), lsw)
