"""Thermal states of a spin lattice by Metropolis Monte Carlo, vectorised by sublattice.

A sweep visits the sublattices of ``vertex_colours`` in turn (two for a bipartite lattice:
the checkerboard). No bond joins two sites of a sublattice, so every site of one proposes and
accepts at once, independently: the energy change of site i is

    ΔE_i = g_i·(S_i' − S_i) − K_i [(n_i·S_i')² − (n_i·S_i)²],   g_i = ∂(H − anisotropy)/∂S_i,

exact because the bond and Zeeman terms are linear in S_i with the other sublattices fixed.
The proposal turns S_i by a Gaussian angle vector of ``spread`` radians per component (a
symmetric proposal: the density of S_i' depends only on its angle to S_i), accepted with
probability min(1, e^{−ΔE_i/T}) (Metropolis, Rosenbluth, Rosenbluth, Teller, Teller, J. Chem.
Phys. 21 (1953) 1087). Each move keeps |S_i|. Detailed balance holds per sublattice update,
so the sweep leaves exp(−H/T) invariant.

Everything is one ``lax.scan`` over sweeps: ``jit`` and ``vmap`` (replicas, temperatures)
apply; the key is explicit, so a run is reproducible.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._bounds import count as check_count
from ..core._errors import InputError
from ..core._state import host_values
from ._spin_flows import turn
from ._spin_langevin import check_number
from ._spin_lattice import SpinLattice, vertex_colours


class MonteCarlo(NamedTuple):
    """A Metropolis run: ``final`` state (the input's shape), ``energy`` H after each sweep
    (sweeps,), ``acceptance`` the fraction of accepted moves over the run.

    >>> import jax, jaxsplit
    >>> ring = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 8), exchange=1.0)
    >>> runs = jax.vmap(lambda k: jaxsplit.metropolis(ring, 1.0, ring.uniform(), k, 50))(
    ...     jax.random.split(jax.random.PRNGKey(0), 4))                 # four replicas
    >>> runs.final.shape, runs.energy.shape
    ((4, 8, 3), (4, 50))
    """

    final: jax.Array
    energy: jax.Array
    acceptance: jax.Array


def default_spread(system: SpinLattice, temperature) -> float:
    """min(π, √(2T/E)) radians with E the largest per-site energy scale Σ_bonds |J| + |B| + 2|K|
    (times the spin length): acceptance near one half from high to low T; 1.0 where a parameter
    is traced."""
    lat = system.lattice
    values = (system.exchange, system.anisotropic, system.field, system.anisotropy, system.spin_length, temperature)
    if not all(is_concrete_value(v) for v in values):
        return 1.0  # traced parameters (a system passed through jit): give spread= for your case
    j = np.broadcast_to(np.abs(host_values(system.exchange, whole=True)) + np.abs(
        host_values(system.anisotropic, whole=True)), (lat.n_bonds,))
    per_site = np.bincount(lat.bonds.reshape(-1), weights=np.repeat(j, 2), minlength=lat.n_sites)
    per_site = per_site + np.linalg.norm(np.broadcast_to(host_values(system.field, whole=True), (lat.n_sites, 3)), axis=-1)
    per_site = per_site + 2 * np.abs(np.broadcast_to(host_values(system.anisotropy, whole=True), (lat.n_sites,)))
    scale = float(np.max(per_site * np.broadcast_to(host_values(system.spin_length, whole=True), (lat.n_sites,))))
    t = float(host_values(jnp.asarray(temperature)))
    return float(np.pi) if scale == 0 else float(min(np.pi, np.sqrt(2 * t / scale)))


def metropolis(system, temperature, state, key, sweeps: int, *, spread=None) -> MonteCarlo:
    """``sweeps`` Metropolis sweeps of ``system`` (a ``spin_lattice``) at ``temperature`` T >= 0
    from ``state`` ((N, 3) or the lattice's shape + (3,)), random numbers from ``key`` (a raw
    ``jax.random.PRNGKey``); ``spread`` the proposal's Gaussian angle in radians (default
    ``default_spread``). See the module docstring. Returns a ``MonteCarlo``.

    >>> import jax, jaxsplit
    >>> chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 32), exchange=1.0)
    >>> run = jaxsplit.metropolis(chain, 0.5, chain.uniform(), jax.random.PRNGKey(0), 200)
    >>> run.final.shape, run.energy.shape, 0.2 < float(run.acceptance) < 0.9
    ((32, 3), (200,), True)
    """
    if not isinstance(system, SpinLattice):
        raise InputError(f"metropolis samples a spin lattice (jaxsplit.spin_lattice), got {type(system).__name__}")
    temperature = check_number(temperature, "temperature")
    sweeps = check_count(sweeps, "sweeps", 1)
    if spread is None:
        spread = default_spread(system, temperature)
    spread = check_number(spread, "spread", "> 0")
    state = system.check_state(state)
    s = system.sites(state)
    if s.ndim != 2:
        raise InputError(f"metropolis samples one state (vmap for replicas), got shape {tuple(jnp.shape(state))}")
    dtype = s.dtype
    masks = [jnp.asarray(system._mask(group), dtype) for group in vertex_colours(system.lattice)]
    t = jnp.asarray(temperature, dtype)
    k = jnp.broadcast_to(jnp.asarray(system.anisotropy, dtype), (system.n_sites,))
    n = jnp.broadcast_to(jnp.asarray(system.axis, dtype), (system.n_sites, 3))
    sigma = jnp.asarray(spread, dtype)

    def field(y):
        return jax.grad(lambda z: jnp.sum(system._no_anisotropy_energy(z)))(y)

    def update(y, mask, draw):
        turn_key, accept_key = jax.random.split(draw)
        proposal = turn(y, sigma * jax.random.normal(turn_key, y.shape, dtype))
        g = field(y)
        de = jnp.sum(g * (proposal - y), axis=-1) - k * (jnp.sum(n * proposal, -1) ** 2 - jnp.sum(n * y, -1) ** 2)
        u = jax.random.uniform(accept_key, de.shape, dtype)
        accept = (de <= 0) | (u < jnp.exp(-de / t))
        accept = accept & (mask[:, 0] > 0)
        return jnp.where(accept[:, None], proposal, y), jnp.sum(accept, dtype=dtype)

    def sweep(carry, draw):
        y, accepted = carry
        for mask, sub in zip(masks, jax.random.split(draw, len(masks))):
            y, a = update(y, mask, sub)
            accepted = accepted + a
        return (y, accepted), system.hamiltonian(y)

    (final, accepted), energy = jax.lax.scan(sweep, (s, jnp.zeros((), dtype)), jax.random.split(key, sweeps))
    acceptance = accepted / (sweeps * system.n_sites)
    return MonteCarlo(final.reshape(jnp.shape(state)), energy, acceptance)


def is_concrete_value(x) -> bool:
    return not isinstance(x, jax.core.Tracer)
