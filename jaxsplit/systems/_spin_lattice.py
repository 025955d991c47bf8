"""Classical spins on a lattice or any bond graph: a Lie–Poisson system on so(3)*ᴺ, split into
exact bond and site flows.

Convention (stated once, tested in ``tests/test_spin_lattice.py``):

    {S_i^a, S_j^b} = δ_ij ε_abc S_i^c,   so   Ṡ_i = {S_i, H} = ∂H/∂S_i × S_i = −S_i × ∂H/∂S_i,

the Landau–Lifshitz form of Sunny.jl and most of the field; in ``ravel`` order of an (N, 3)
state the Poisson matrix is block-diagonal with blocks −hat(S_i) (the free rigid body of this
package uses +hat(m): the opposite sign). A spin in a field B (H = −B·S) precesses about B
with angular velocity −B: clockwise seen from the tip of B, S^x + iS^y ∝ e^{−i|B|t} for B
along z, so spin waves appear at positive frequency in ``structure_factor``.

    H = Σ_bonds [−J_b S_i·S_j − Δ_b S_i^z S_j^z + D_b·(S_i × S_j)] − Σ_i [K_i (n_i·S_i)² + B_i·S_i]

J > 0 ferromagnetic, J < 0 antiferromagnetic; each bond (i, j) is ordered (the DM term is
odd in it). Casimirs: |S_i| (length ``spin_length`` s_i). Total magnetisation along e is
conserved when every term is invariant under rotations about e (``magnetisation_axis``).

Splits (each a tuple of flows, ``_spin_flows``):

* ``"bonds"``: per colour of the lattice's edge colouring (a matching, so its bonds commute)
  the exact exchange flow; with DM, J·1 + hat(D) = J'[R_d(θ) − (1 − cos θ) d dᵀ] (J' =
  sign(J) √(J² + |D|²), sin θ = |D|/J', d = D/|D|) is a twisted Heisenberg bond plus an
  Ising bond along d; XXZ adds an Ising bond along z; then the uniaxial anisotropy and the
  Zeeman rotation. Every piece is an exact Hamiltonian flow, so every scheme of the registry
  gives a Poisson map of its order. On a periodic chain, square or simple-cubic lattice with
  even lengths and one J (no DM, no XXZ) the colours run as pair flows on reshapes of a
  components-first state (``_spin_pairs``, ``pair_layout``): the same map to round-off.
* ``"sublattice"`` (Frank, Huang, Landau, Can. J. Phys. 75 (1997) 1; Krech, Bunker, Landau,
  Comput. Phys. Commun. 111 (1998) 1): sites coloured so that no bond joins two of a colour;
  each sublattice precesses about the frozen field of the others (exchange and Zeeman);
  the anisotropy is its exact piece. Conserves the energy of exchange + field exactly per
  piece; not a Poisson map (audited by ``jaxsplit spins-audit``).
* ``"sweep"``: one piece per site, each spin turning about its current local field with the
  others frozen; Strang gives the symmetric sequential sweep of Omelyan, Mryglod, Folk, PRL
  86 (2001) 898 and LAMMPS SPIN's ``fix nve/spin`` (Tranchida et al., J. Comput. Phys. 372
  (2018) 406). Small lattices only (one flow per site).

Implicit and explicit baselines for any H: ``spherical_midpoint`` and ``heun``
(``_spin_integrators``).
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._state import host_values
from ..lattices._graph import Lattice
from ._base import AbstractSystem
from ._rigid_body import as_float_array, is_concrete
from ._spin_flows import (
    BondExchange,
    BondIsing,
    FrozenField,
    SiteRotation,
    StaticIndex,
    _site_axes,
    as_sites,
    partners,
    per_site,
    turn,
)
from ._spin_pairs import PairExchange, PairLayout
from ._validate import _show

SWEEP_MAX_SITES = 256  # one flow per site: beyond this the compile time, not the run, dominates


def _per(value, count: int, name: str, what: str, vector: bool = False):
    """A finite scalar (or 3-vector) or one per bond/site: checked where concrete."""
    arr = as_float_array(value, name)
    if is_concrete(arr):
        a = host_values(arr)
        tail = (3,) if vector else ()
        if arr.shape not in (tail, (count,) + tail):
            one = "a 3-vector" if vector else "a number"
            raise InputError(f"{name} must be {one} or one per {what} (shape {(count,) + tail}), got shape {arr.shape}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"{name} must be finite, got {_show(a[~np.isfinite(a)])}")
    return arr


def _present(value) -> bool:
    """Whether a term is there: any nonzero entry (a traced value counts as present)."""
    return value is not None and (not is_concrete(value) or bool(np.any(host_values(value, whole=True) != 0)))


def _pick(value, index, vector: bool = False):
    """A per-bond parameter's entries for the bonds ``index``, (len(index),) or (len(index), 3)
    (a shared value broadcast)."""
    shared = value.ndim == (1 if vector else 0)
    tail = (3,) if vector else ()
    return jnp.broadcast_to(value, (len(index),) + tail) if shared else value[index]


def vertex_colours(lattice: Lattice) -> tuple:
    """Sites coloured so that no bond joins two sites of one colour: two for a bipartite graph
    (breadth-first), else greedy in order of decreasing degree (at most Δ + 1); tuple of site arrays."""
    neighbours = lattice.neighbours()
    colour = np.full(lattice.n_sites, -1)
    bipartite = True
    for root in range(lattice.n_sites):
        if colour[root] >= 0:
            continue
        colour[root], queue = 0, [root]
        while queue and bipartite:
            u = queue.pop()
            for v in neighbours[u]:
                if colour[v] < 0:
                    colour[v] = 1 - colour[u]
                    queue.append(v)
                elif colour[v] == colour[u]:
                    bipartite = False
    if not bipartite:
        colour[:] = -1
        for u in sorted(range(lattice.n_sites), key=lambda s: -len(neighbours[s])):
            taken = {colour[v] for v in neighbours[u]}
            colour[u] = next(c for c in range(len(taken) + 1) if c not in taken)
    return tuple(np.flatnonzero(colour == c) for c in range(colour.max() + 1))


class SpinLattice(AbstractSystem):
    """Classical spins on ``lattice`` (a ``jaxsplit.lattices.Lattice``); see the module
    docstring for H, the convention and the splits. Parameters are traced array fields;
    the lattice is static. State: (N, 3) or ``lattice.shape + (3,)``, float64 or float32
    (leading batch axes allowed for the flows).

    >>> import jax.numpy as jnp, jaxsplit
    >>> chain = jaxsplit.lattices.lattice("chain", 8)
    >>> system = jaxsplit.systems.spin_lattice(chain, exchange=1.0, field=(0.0, 0.0, 0.1))
    >>> s0 = system.perturbed(system.uniform((0.0, 0.0, 1.0)), 0.1, seed=0)
    >>> s1 = jaxsplit.integrate(jaxsplit.splitting(system, "strang", "bonds"), s0, 0.05, 200).final
    >>> bool(jnp.max(jnp.abs(jnp.linalg.norm(s1, axis=-1) - 1)) < 1e-13)       # |S_i| kept
    True
    """

    lattice: Lattice = eqx.field(static=True)
    exchange: jax.Array
    anisotropic: jax.Array
    dm: jax.Array | None
    anisotropy: jax.Array
    axis: jax.Array
    field: jax.Array
    spin_length: jax.Array
    refused_splits: ClassVar[dict[str, str]] = {
        "axes": "a spin lattice has no body axes; its splits are 'bonds', 'sublattice' and 'sweep'",
        "casimir": "a spin lattice has no body axes; its splits are 'bonds', 'sublattice' and 'sweep'"}

    def __init__(self, lattice, exchange=1.0, anisotropic=0.0, dm=None, anisotropy=0.0, axis=(0.0, 0.0, 1.0),
                 field=(0.0, 0.0, 0.0), spin_length=1.0):
        if not isinstance(lattice, Lattice):
            raise InputError(f"spin_lattice needs a lattice (jaxsplit.lattices.lattice(...) or .graph(...)), got "
                             f"{type(lattice).__name__}")
        n, b = lattice.n_sites, lattice.n_bonds
        self.lattice = lattice
        self.exchange = _per(exchange, b, "exchange", "bond")
        self.anisotropic = _per(anisotropic, b, "anisotropic (the XXZ Δ)", "bond")
        self.dm = None if dm is None else _per(dm, b, "dm", "bond", vector=True)
        self.anisotropy = _per(anisotropy, n, "anisotropy", "site")
        axis = _per(axis, n, "axis", "site", vector=True)
        size = jnp.linalg.norm(axis, axis=-1, keepdims=True)
        if is_concrete(size) and np.any(host_values(size) == 0):
            raise InputError("axis (the anisotropy axis n) must be a nonzero vector, got (0, 0, 0)")
        self.axis = axis / size
        self.field = _per(field, n, "field", "site", vector=True)
        self.spin_length = _per(spin_length, n, "spin_length", "site")
        lengths = host_values(self.spin_length)
        if lengths is not None and not np.all(lengths > 0):
            raise InputError(f"spin_length must be > 0, got {_show(lengths)}")

    # ------------------------------------------------------------------ structure
    @property
    def n_sites(self) -> int:
        return self.lattice.n_sites

    def sites(self, x):
        """x as (..., N, 3)."""
        x = jnp.asarray(x)
        try:
            return as_sites(x, self.n_sites)[0]
        except ValueError:
            raise InputError(f"a state of {self.lattice!r} has shape ({self.n_sites}, 3) or {self.lattice.shape + (3,)}"
                             f", got {x.shape}") from None

    def bond_energy(self, x):
        """The bond terms of H (..., one value per state)."""
        s = self.sites(x)
        si = jnp.take(s, self.lattice.bonds[:, 0], axis=-2)
        sj = jnp.take(s, self.lattice.bonds[:, 1], axis=-2)
        j = jnp.asarray(self.exchange, s.dtype)
        e = -jnp.sum(j * jnp.sum(si * sj, axis=-1), axis=-1)
        e = e - jnp.sum(jnp.asarray(self.anisotropic, s.dtype) * si[..., 2] * sj[..., 2], axis=-1)
        if self.dm is not None:
            e = e + jnp.sum(jnp.asarray(self.dm, s.dtype) * jnp.cross(si, sj), axis=(-2, -1))
        return e

    def zeeman_energy(self, x):
        s = self.sites(x)
        return -jnp.sum(jnp.asarray(self.field, s.dtype) * s, axis=(-2, -1))

    def anisotropy_energy(self, x):
        s = self.sites(x)
        proj = jnp.sum(jnp.asarray(self.axis, s.dtype) * s, axis=-1)
        return -jnp.sum(jnp.asarray(self.anisotropy, s.dtype) * proj * proj, axis=-1)

    def hamiltonian(self, x):
        return self.bond_energy(x) + self.zeeman_energy(x) + self.anisotropy_energy(x)

    def local_field(self, x):
        """∂H/∂S_i, (..., N, 3): the angular velocity of each spin, Ṡ_i = ∂H/∂S_i × S_i."""
        s = self.sites(x)
        return jax.grad(lambda y: jnp.sum(self.hamiltonian(y)))(s)

    def vector_field(self, x):
        s = self.sites(x)
        return jnp.cross(self.local_field(s), s).reshape(jnp.shape(x))

    def poisson_matrix(self, x):
        s = self.sites(x)
        if s.ndim != 2:
            raise InputError(f"poisson_matrix acts on one state (vmap for many), got shape {jnp.shape(x)}")
        zero = jnp.zeros_like(s[:, 0])
        blocks = -jnp.stack([jnp.stack([zero, -s[:, 2], s[:, 1]], -1), jnp.stack([s[:, 2], zero, -s[:, 0]], -1),
                             jnp.stack([-s[:, 1], s[:, 0], zero], -1)], -2)  # −hat(S_i)
        n = self.n_sites
        return jnp.einsum("ij,iab->iajb", jnp.eye(n, dtype=s.dtype), blocks).reshape(3 * n, 3 * n)

    def casimirs(self):
        return {"|S_i|": lambda x: jnp.linalg.norm(self.sites(x), axis=-1)}

    def magnetisation_axis(self):
        """The directions e along which Σ S_i is conserved: "all" (isotropic exchange, no
        field, no anisotropy), a unit vector (every field, anisotropy axis, DM vector and the
        XXZ axis z along one line), or None (also when a parameter is traced)."""
        values = [self.anisotropic, self.dm, self.anisotropy, self.axis, self.field]
        if not all(v is None or is_concrete(v) for v in values):
            return None
        directions = []
        if _present(self.anisotropic):
            directions.append(np.array([0.0, 0.0, 1.0]))
        if _present(self.dm):
            directions += list(host_values(self.dm, whole=True).reshape(-1, 3))
        if _present(self.field):
            directions += list(host_values(self.field, whole=True).reshape(-1, 3))
        k = np.broadcast_to(host_values(self.anisotropy, whole=True), (self.n_sites,))
        n = np.broadcast_to(host_values(self.axis, whole=True), (self.n_sites, 3))
        directions += list(n[k != 0])
        directions = [d / np.linalg.norm(d) for d in directions if np.linalg.norm(d) > 0]
        if not directions:
            return "all"
        e = directions[0]
        if all(np.linalg.norm(np.cross(d, e)) < 1e-12 for d in directions):
            return e
        return None

    def magnetisation(self, x):
        """Σ_i S_i, (..., 3)."""
        return jnp.sum(self.sites(x), axis=-2)

    def invariants(self):
        out = {"energy": self.hamiltonian, **self.casimirs()}
        axis = self.magnetisation_axis()
        if isinstance(axis, str):
            out["magnetisation"] = self.magnetisation
        elif axis is not None:
            e = jnp.asarray(axis)
            out["magnetisation along e"] = lambda x: self.magnetisation(x) @ e.astype(jnp.asarray(x).dtype)
        return out

    def check_state(self, x):
        """``x`` as a state (finite, shape (N, 3) or lattice shape + (3,), |S_i| = spin_length to
        √ε where concrete); returns it."""
        x = jnp.asarray(x)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            raise InputError(f"a spin state must be float32 or float64, got {x.dtype}")
        try:
            k = _site_axes(x.shape, self.n_sites)
        except ValueError:
            return self.sites(x)  # its message names the shapes allowed
        a, where = host_values(x, where=True)  # spread over processes: the block held here
        if a is not None:
            if not np.all(np.isfinite(a)):
                raise InputError("a spin state must be finite")
            # the sites' own lengths, laid out as x and cut as the block (a global spin_length whole)
            sites = np.arange(self.n_sites).reshape(x.shape[x.ndim - 1 - k:-1])
            lengths = np.broadcast_to(host_values(self.spin_length, whole=True), (self.n_sites,))[sites]
            lengths = np.broadcast_to(lengths, x.shape[:-1])[... if where is ... else where[:-1]]
            ratio = np.linalg.norm(a, axis=-1) / lengths
            tol = float(np.sqrt(np.finfo(a.dtype).eps))
            if np.any(np.abs(ratio - 1) > tol):
                raise InputError(f"|S_i| must equal spin_length (to {tol:.1e} relative), got |S_i|/s_i = "
                                 f"{_show(ratio[np.abs(ratio - 1) > tol])}")
        return x

    # ------------------------------------------------------------------ states
    def _lengths(self, dtype):
        return jnp.broadcast_to(jnp.asarray(self.spin_length, dtype), (self.n_sites,))[:, None]

    def uniform(self, direction=(0.0, 0.0, 1.0), dtype=None):
        """Every spin along ``direction``, lengths s_i: an (N, 3) state."""
        d = jnp.asarray(direction, dtype=dtype or jnp.result_type(float))
        if d.shape != (3,) or not float(jnp.linalg.norm(d)) > 0:
            raise InputError(f"direction must be a nonzero 3-vector, got {np.asarray(d).tolist()}")
        return self._lengths(d.dtype) * (d / jnp.linalg.norm(d))[None, :]

    def neel(self, direction=(0.0, 0.0, 1.0), dtype=None):
        """Spins ±``direction`` on the two sublattices of a bipartite lattice (the Néel state)."""
        groups = vertex_colours(self.lattice)
        if len(groups) != 2:
            raise InputError(f"the Néel state needs a bipartite lattice; {self.lattice.name} of size "
                             f"{self.lattice.size} is not (its sites need {len(groups)} colours)")
        sign = np.ones(self.n_sites)
        sign[groups[1]] = -1
        s = self.uniform(direction, dtype)
        return s * jnp.asarray(sign, s.dtype)[:, None]

    def random_state(self, seed: int = 0, dtype=None):
        """Spins in uniformly random directions (NumPy generator ``seed``), lengths s_i."""
        v = np.random.default_rng(seed).normal(size=(self.n_sites, 3))
        v = jnp.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True), dtype=dtype or jnp.result_type(float))
        return self._lengths(v.dtype) * v

    def perturbed(self, state, amplitude: float, seed: int = 0, zero_mean: bool = False):
        """``state`` with each spin turned by a small random angle (Gaussian tangent increments
        of size ~``amplitude`` radians): lengths kept exactly. ``zero_mean``: the increments'
        sum removed (to first order the total magnetisation is that of ``state``; a net
        moment would make a whole ordered state precess, splitting its spin-wave peaks)."""
        s = self.sites(state)
        a = np.asarray(s, dtype=float)
        unit = a / np.linalg.norm(a, axis=-1, keepdims=True)
        delta = np.random.default_rng(seed).normal(scale=float(amplitude), size=a.shape)
        for _ in range(4 if zero_mean else 1):  # onto the tangent planes, mean removed
            delta = delta - unit * np.sum(unit * delta, axis=-1, keepdims=True)
            if zero_mean:
                delta = delta - np.mean(delta, axis=0)
        delta = delta - unit * np.sum(unit * delta, axis=-1, keepdims=True)
        return turn(s, jnp.asarray(np.cross(unit, delta), s.dtype)).reshape(jnp.shape(state))

    # ------------------------------------------------------------------ splits
    def splits(self):
        return {"bonds": self.bonds_split, "sublattice": self.sublattice_split, "sweep": self.sweep_split}

    def _site_pieces(self, zeeman: bool = True, shape=None) -> tuple:
        out = ()
        if _present(self.anisotropy):
            out += (SiteRotation(self.axis, self.anisotropy, self.n_sites, shape),)
        if zeeman and _present(self.field):
            out += (SiteRotation(self.field, None, self.n_sites, shape),)
        return out

    def pair_layout(self) -> PairLayout | None:
        """Where the bond split runs its fast path (``_spin_pairs``): a periodic chain, square or
        simple-cubic lattice, every length even, one exchange J shared by every bond, no DM and
        no XXZ term; else None (the gather path)."""
        lat = self.lattice
        if lat.name not in ("chain", "square", "simple-cubic") or not lat.periodic or any(n % 2 for n in lat.size):
            return None
        if self.exchange.ndim != 0 or self.dm is not None and _present(self.dm) or _present(self.anisotropic):
            return None
        if not _present(self.exchange):
            return None
        # the colours are the (axis, parity) matchings, in that order (``lattices._lattices``): each
        # bond of colour c must join a site to its partner along the axis (a partner map, no sort)
        if len(lat.colours) != 2 * len(lat.size):
            return None
        sites = np.arange(lat.n_sites).reshape(lat.size)
        partner = np.empty(lat.n_sites, np.int64)
        for c, colour in enumerate(lat.colours):
            axis, parity = divmod(c, 2)
            first = np.take(sites, np.arange(parity, lat.size[axis], 2), axis=axis).ravel()
            second = np.take(sites, (np.arange(parity, lat.size[axis], 2) + 1) % lat.size[axis], axis=axis).ravel()
            partner[first], partner[second] = second, first
            pairs = lat.bonds[colour]
            if len(pairs) != len(first) or not np.array_equal(partner[pairs[:, 0]], pairs[:, 1]):
                return None
        return PairLayout(tuple(lat.size))

    def bonds_split(self) -> tuple:
        """Exact flows: per colour the exchange (twisted by DM), DM's Ising part, XXZ's Ising
        part; then anisotropy and Zeeman (module docstring)."""
        lat = self.lattice
        layout = self.pair_layout()
        if layout is not None:  # the fast path: colours as reshapes, components first (``_spin_pairs``)
            longest = jnp.max(self.spin_length)
            pieces = tuple(PairExchange(self.exchange, longest, axis, parity, layout.shape)
                           for axis in range(len(layout.shape)) for parity in (0, 1))
            return pieces + self._site_pieces(shape=layout.shape)
        has_dm, has_xxz = _present(self.dm), _present(self.anisotropic)
        has_exchange = has_dm or _present(self.exchange)
        pieces = []
        for colour in lat.colours:
            pairs = lat.bonds[colour]
            n, partner = lat.n_sites, StaticIndex(partners(lat.n_sites, pairs))
            j = _pick(self.exchange, colour)
            if has_exchange and not has_dm:
                pieces.append(BondExchange(partner, per_site(n, pairs, j), None))
            elif has_dm:
                d = _pick(self.dm, colour, vector=True)
                size = jnp.linalg.norm(d, axis=-1)
                sign = jnp.where(j < 0, -1.0, 1.0)
                j_prime = sign * jnp.sqrt(j * j + size * size)
                theta = sign * jnp.arctan2(size, jnp.abs(j))
                unit = d / jnp.where(size > 0, size, 1.0)[..., None]
                twist = theta[..., None] * unit
                pieces.append(BondExchange(partner, per_site(n, pairs, j_prime), per_site(n, pairs, twist, -twist)))
                pieces.append(BondIsing(partner, per_site(n, pairs, -j_prime * (1 - jnp.cos(theta))),
                                        per_site(n, pairs, unit)))
            if has_xxz:
                pieces.append(BondIsing(partner, per_site(n, pairs, _pick(self.anisotropic, colour)),
                                        jnp.array([0.0, 0.0, 1.0])))
        pieces += self._site_pieces()
        return tuple(pieces) or (SiteRotation(self.field, None, self.n_sites),)

    def _mask(self, sites):
        mask = np.zeros((self.n_sites, 1))
        mask[np.asarray(sites)] = 1.0
        return jnp.asarray(mask)

    def _no_anisotropy_energy(self, x):
        return self.bond_energy(x) + self.zeeman_energy(x)

    def sublattice_split(self) -> tuple:
        """Each sublattice (``vertex_colours``) turning about the frozen field of the others
        (exchange and Zeeman), then the exact anisotropy piece."""
        flows = tuple(FrozenField(self._no_anisotropy_energy, self._mask(group), True, self.n_sites)
                      for group in vertex_colours(self.lattice))
        return flows + self._site_pieces(zeeman=False)

    def sweep_split(self) -> tuple:
        """One piece per site in index order: the spin turns about its current local field (all
        of H), the others frozen; a group flow where the site has no anisotropy."""
        if self.n_sites > SWEEP_MAX_SITES:
            raise InputError(f"split 'sweep' composes one flow per site: at most {SWEEP_MAX_SITES} sites, got "
                             f"{self.n_sites}; use 'bonds' (exact) or 'sublattice'")
        k = self.anisotropy
        free = [True] * self.n_sites if not is_concrete(k) else np.broadcast_to(host_values(k, whole=True) == 0, (self.n_sites,))
        if not is_concrete(k):
            free = [False] * self.n_sites
        return tuple(FrozenField(self.hamiltonian, self._mask([i]), bool(free[i]), self.n_sites)
                     for i in range(self.n_sites))


def spin_lattice(lattice, *, exchange=1.0, anisotropic=0.0, dm=None, anisotropy=0.0, axis=(0.0, 0.0, 1.0),
                 field=(0.0, 0.0, 0.0), spin_length=1.0) -> SpinLattice:
    """Classical spins on ``lattice`` (``jaxsplit.lattices.lattice(...)`` or ``.graph(...)``):

    H = Σ_bonds [−J S_i·S_j − Δ S_i^z S_j^z + D·(S_i × S_j)] − Σ_i [K (n·S_i)² + B·S_i]

    with ``exchange`` J, ``anisotropic`` Δ (XXZ), ``dm`` D (a 3-vector), each a scalar or one
    per bond; ``anisotropy`` K, ``axis`` n (normalised), ``field`` B, ``spin_length`` s, each
    shared or one per site. Ṡ_i = ∂H/∂S_i × S_i. See ``SpinLattice``.

    >>> import jaxsplit
    >>> system = jaxsplit.systems.spin_lattice(jaxsplit.lattices.lattice("square", 4), exchange=-1.0)
    >>> float(system.hamiltonian(system.neel()))        # 32 antiparallel bonds, J = −1
    -32.0
    """
    return SpinLattice(lattice, exchange, anisotropic, dm, anisotropy, axis, field, spin_length)
