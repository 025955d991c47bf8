"""The dynamical structure factor S(q, ω) of a spin trajectory on a lattice: a windowed
space–time Fourier transform.

For spins S_i(t_k), t_k = k dt (k = 0..T−1), at positions r_i, with δS_i = S_i − its time
mean (``connected=True``: the static order's Bragg peak at ω = 0 removed) and a window w_k
(Hann by default),

    X^α(q, ω) = Σ_k w_k e^{iω t_k} Σ_i e^{−iq·r_i} δS_i^α(t_k),
    S(q, ω) = dt / (N Σ_k w_k²) Σ_{α in components} |X^α(q, ω)|²,

on the frequencies ω_n = 2πn/(T dt) (resolution Δω = 2π/(T dt), |ω| up to the Nyquist π/dt)
and on the wavevectors of the lattice's periodic box, q = Σ_a (m_a/L_a) b_a (b_a the
reciprocal vectors, a_a·b_b = 2π δ_ab; m_a = 0..L_a−1). Normalisation: by Parseval,
Σ_n S(q, ω_n) Δω/(2π) = Σ_k w_k² |δS(q, t_k)|² / (N Σ_k w_k²), the window-weighted time
average of |δS(q, t)|²/N: the equal-time structure factor (per spin, summed over the
components). A stationary trajectory gives the usual
S(q, ω) = (1/N) Σ_ij e^{−iq·(r_i − r_j)} ∫ dt e^{iωt} ⟨δS_i(t)·δS_j(0)⟩ (Sunny.jl's
convention up to its constant factors), smoothed by the window's spectrum. ``segments`` > 1
averages that many half-overlapping windows (Welch): less noise, coarser Δω.

With the convention Ṡ_i = ∂H/∂S_i × S_i (``jaxsplit.systems.spin_lattice``) a ferromagnet's
spin waves S^x + iS^y ∝ e^{i(q·r − ωt)} sit at (q, +ω(q)); real components also put each at
(−q, −ω(q)).
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..lattices._graph import Lattice


class StructureFactor(NamedTuple):
    """S(q, ω) on the lattice's wavevector grid (module docstring).

    ``intensity`` (*size, n_ω) real, in the trajectory's dtype; ``omega`` (n_ω,) increasing
    (negative to positive); ``q`` (*size, d) Cartesian wavevectors, grid index m_a = 0..L_a−1
    along each axis; ``resolution`` Δω = 2π/(T dt) of one window.
    """

    intensity: object
    omega: np.ndarray
    q: np.ndarray
    resolution: float

    def peak_frequencies(self, positive: bool = True) -> np.ndarray:
        """The frequency of the largest intensity at each q (over ω > 0 when ``positive``): (*size,)."""
        s = np.asarray(self.intensity)
        omega = self.omega
        if positive:
            keep = omega > 0
            s, omega = s[..., keep], omega[keep]
        return omega[np.argmax(s, axis=-1)]


def _window(name: str, length: int) -> np.ndarray:
    if name == "hann":
        return np.hanning(length) if length > 2 else np.ones(length)
    if name in ("none", "rectangular", None):
        return np.ones(length)
    raise InputError(f"window must be 'hann' or 'none', got {name!r}")


def structure_factor(trajectory, lattice: Lattice, dt: float | None = None, *, components: str = "xyz",
                     window: str = "hann", connected: bool = True, segments: int = 1) -> StructureFactor:
    """S(q, ω) of ``trajectory`` on ``lattice`` (module docstring for the definition and its
    normalisation).

    ``trajectory``: states (T, N, 3) or (T, *lattice.shape, 3), or a ``Solution`` (its saved
    states, and its time step when ``dt`` is None); ``dt`` the time between saved states;
    ``components`` the spin components summed ("xyz", "xy", "z", ...); ``window`` "hann" or
    "none"; ``connected`` subtracts each spin's time mean; ``segments`` half-overlapping
    windows averaged. The lattice must be a named one (its cell gives the wavevectors).

    >>> import jax.numpy as jnp, numpy as np, jaxsplit
    >>> chain = jaxsplit.lattices.lattice("chain", 8)
    >>> t = 0.5 * np.arange(64)[:, None]                          # one wave, q = 2π·1/8, ω = 1
    >>> r = np.arange(8)[None, :]
    >>> wave = np.stack([np.cos(2 * np.pi * r / 8 - t), np.sin(2 * np.pi * r / 8 - t), np.zeros((64, 8))], -1)
    >>> sqw = jaxsplit.structure_factor(jnp.asarray(wave), chain, 0.5, components="xy")
    >>> s, up = np.asarray(sqw.intensity), sqw.omega > 0        # this wave is at (q, +ω), its mirror at (−q, −ω)
    >>> round(float(sqw.peak_frequencies()[1]), 2), bool(s[1, up].max() > 100 * s[7, up].max())
    (0.98, True)
    """
    if not isinstance(lattice, Lattice) or lattice.cell is None:
        raise InputError("structure_factor needs a named lattice (jaxsplit.lattices.lattice(...)): its cell gives "
                         f"the wavevectors; got {lattice!r}")
    if dt is None and hasattr(trajectory, "t") and hasattr(trajectory, "x"):
        times = np.asarray(trajectory.t)
        dt = float(times[1] - times[0]) if len(times) > 1 else None
    if hasattr(trajectory, "x") and hasattr(trajectory, "t"):
        trajectory = trajectory.x
    x = jnp.asarray(trajectory)
    if dt is None or not np.isfinite(float(dt)) or float(dt) <= 0:
        raise InputError(f"dt (the time between saved states) must be a positive number, got {dt!r}")
    dt = float(dt)
    n_basis = len(lattice.basis)
    if x.ndim < 3 or x.shape[-1] != 3 or int(np.prod(x.shape[1:-1])) != lattice.n_sites:
        raise InputError(f"trajectory must have shape (T, {lattice.n_sites}, 3) or (T, *{lattice.shape}, 3), got "
                         f"{x.shape}")
    bad = sorted(set(components) - set("xyz"))
    if not components or bad or len(set(components)) != len(components):
        raise InputError(f"components must be distinct letters of 'xyz', got {components!r}")
    if isinstance(segments, bool) or not isinstance(segments, int) or segments < 1:
        raise InputError(f"segments must be an integer >= 1, got {segments!r}")
    size = tuple(lattice.size)
    steps = x.shape[0]
    length = steps if segments == 1 else (2 * steps) // (segments + 1)
    if length < 2:
        raise InputError(f"a trajectory of {steps} states is too short for {segments} segments")
    x = x.reshape((steps,) + size + (n_basis, 3))[..., ["xyz".index(c) for c in components]]
    d = len(size)
    # the wavevectors: q = Σ_a (m_a/L_a) b_a, b = 2π (cellᵀ)⁻¹ as rows
    reciprocal = 2 * np.pi * np.linalg.inv(lattice.cell).T
    grid = np.stack(np.meshgrid(*(np.arange(s) / s for s in size), indexing="ij"), axis=-1)
    q = grid @ reciprocal
    phase = jnp.asarray(np.exp(-1j * q @ lattice.basis.T))  # (*size, n_basis): e^{−iq·b_s}
    w = _window(window, length)
    total = 0.0
    starts = [0] if segments == 1 else [k * (length // 2) for k in range(segments)]
    for start in starts:
        piece = x[start:start + length]
        if connected:
            piece = piece - jnp.mean(piece, axis=0)
        spatial = jnp.fft.fftn(piece, axes=tuple(range(1, d + 1)))  # Σ_c e^{−2πi m·c/L}
        spatial = jnp.einsum("t...sc,...s->t...c", spatial, phase.astype(spatial.dtype))
        weighted = spatial * jnp.asarray(w, x.dtype).reshape((length,) + (1,) * (d + 1))
        temporal = length * jnp.fft.ifft(weighted, axis=0)  # Σ_k e^{+iω t_k}
        total = total + jnp.sum(jnp.abs(temporal) ** 2, axis=-1)
    intensity = total * (dt / (lattice.n_sites * float(np.sum(w * w)) * len(starts)))
    intensity = jnp.moveaxis(jnp.fft.fftshift(intensity, axes=0), 0, -1)
    omega = np.fft.fftshift(np.fft.fftfreq(length, d=dt)) * 2 * np.pi
    return StructureFactor(intensity.astype(x.dtype), omega, q, 2 * np.pi / (length * dt))
