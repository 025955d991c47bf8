"""S(q, ω): peaks on the linear spin-wave dispersions (physics nobody here wrote), the
documented normalisation, and the one-line errors."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.lattices import graph, lattice

ONE_BIN = 1.0  # acceptance: every resolved peak within one frequency bin of linear spin-wave theory
RESOLVED = 1e-6  # a q is resolved where its total weight exceeds this fraction of the median


def _peaks_within_one_bin(sqw, theory):
    weight = np.asarray(sqw.intensity).sum(axis=-1)
    resolved = weight > RESOLVED * np.median(weight)
    off = np.abs(sqw.peak_frequencies() - theory) / sqw.resolution
    assert resolved.mean() > 0.9
    assert np.all(off[resolved] <= ONE_BIN + 1e-9), np.round(off, 2)


def test_ferromagnetic_chain_in_a_field():
    """H = −J Σ S_i·S_{i+1} − B Σ S_i^z, S = 1: ω(q) = 2JS(1 − cos q) + B, at ω > 0 (the sense of
    Ṡ_i = ∂H/∂S_i × S_i)."""
    j, b, spin = 1.0, 0.1, 1.0
    chain = lattice("chain", 32)
    system = jaxsplit.spin_lattice(chain, exchange=j, field=(0.0, 0.0, b), spin_length=spin)
    s0 = system.perturbed(system.uniform(), 0.02, seed=0)
    sol = jaxsplit.integrate(jaxsplit.splitting(system, "strang", "bonds"), s0, 0.02, 20480, save_every=10)
    sqw = jaxsplit.structure_factor(sol, chain)  # dt read from the Solution: 0.2
    assert sqw.resolution == pytest.approx(2 * np.pi / (2049 * 0.2))
    _peaks_within_one_bin(sqw, 2 * j * spin * (1 - np.cos(sqw.q[..., 0])) + b)
    # the precession sense: S^+ = S^x + iS^y ∝ e^{i(qr − ωt)}, so its transform with e^{−iqr + iωt}
    # (the convention above) peaks at ω = +ω(q) (at q = 0: the uniform precession, ω = B)
    s_plus = np.asarray(sol.x[:, :, 0] + 1j * sol.x[:, :, 1]).sum(axis=1)
    spectrum = np.abs(np.fft.ifft((s_plus - s_plus.mean()) * np.hanning(len(s_plus))))
    omega = 2 * np.pi * np.fft.fftfreq(len(s_plus), 0.2)
    assert abs(omega[np.argmax(spectrum)] - b) <= sqw.resolution


def test_antiferromagnetic_square_lattice():
    """H = +J Σ S_i·S_j (exchange = −J in this convention), S = 1: ω(q) = 4JS √(1 − γ_q²),
    γ_q = (cos q_x + cos q_y)/2, from the Néel state with a small kick of zero net moment."""
    j = 1.0
    square = lattice("square", 8)
    system = jaxsplit.spin_lattice(square, exchange=-j)
    s0 = system.perturbed(system.neel(), 0.02, seed=1, zero_mean=True)
    sol = jaxsplit.integrate(jaxsplit.splitting(system, "strang", "bonds"), s0, 0.02, 10240, save_every=10)
    sqw = jaxsplit.structure_factor(sol.x, square, 0.2)
    gamma = (np.cos(sqw.q[..., 0]) + np.cos(sqw.q[..., 1])) / 2
    _peaks_within_one_bin(sqw, 4 * j * np.sqrt(1 - gamma**2))


def test_normalisation_is_parseval():
    """Σ_ω S(q, ω) Δω/2π = the window-weighted time average of |δS(q, t)|²/N (module docstring)."""
    rng = np.random.default_rng(0)
    square = lattice("square", (4, 6))
    x = rng.normal(size=(50, 4, 6, 3))
    for window, w in (("none", np.ones(50)), ("hann", np.hanning(50))):
        sqw = jaxsplit.structure_factor(jnp.asarray(x), square, 0.3, window=window)
        assert sqw.intensity.shape == (4, 6, 50) and np.all(np.diff(sqw.omega) > 0)
        dx = x - x.mean(axis=0)
        sq_t = np.abs(np.fft.fft2(dx, axes=(1, 2))) ** 2  # |δS(q, t)|² per component
        expected = np.sum(w[:, None, None] ** 2 * sq_t.sum(-1), axis=0) / (24 * np.sum(w**2))
        got = np.asarray(sqw.intensity).sum(-1) * sqw.resolution / (2 * np.pi)
        np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_basis_sites_get_their_phase():
    """On the honeycomb (two sites per cell) the equal-time weight equals the brute-force sum
    (1/N) mean_t |Σ_i e^{−iq·r_i} S_i(t)|² over the actual site positions."""
    hc = lattice("honeycomb", (3, 4))
    x = np.random.default_rng(1).normal(size=(6, 24, 3))
    sqw = jaxsplit.structure_factor(jnp.asarray(x), hc, 1.0, window="none", connected=False)
    phases = np.exp(-1j * np.einsum("abd,nd->abn", sqw.q, hc.positions))  # (3, 4, N)
    brute = np.mean(np.sum(np.abs(np.einsum("abn,tnc->tabc", phases, x)) ** 2, axis=-1), axis=0) / 24
    got = np.asarray(sqw.intensity).sum(-1) * sqw.resolution / (2 * np.pi)
    np.testing.assert_allclose(got, brute, rtol=1e-12)


@pytest.mark.parametrize("call, message", [
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 3, 3)), graph(3, [[0, 1]]), 0.1), "needs a named lattice"),
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 4, 3)), lattice("chain", 4), 0.1, segments=0),
     "segments must be an integer"),
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 5, 3)), lattice("chain", 4), 0.1), "trajectory must have shape"),
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 4, 3)), lattice("chain", 4), -1.0), "dt (the time between"),
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 4, 3)), lattice("chain", 4), 0.1, components="xw"),
     "components must be distinct letters"),
    (lambda: jaxsplit.structure_factor(jnp.zeros((4, 4, 3)), lattice("chain", 4), 0.1, window="kaiser"),
     "window must be 'hann' or 'none'"),
])
def test_bad_input(call, message):
    with pytest.raises(jaxsplit.InputError) as err:
        call()
    assert message in str(err.value)
