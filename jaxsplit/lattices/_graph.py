"""A bond graph and its edge colouring: geometry, nothing about dynamics.

A ``Lattice`` is a frozen record of sites (positions), bonds (pairs of site indices) and an
edge colouring ``colours``: a tuple of integer arrays of bond indices, each colour a
*matching* (no two of its bonds share a site). Bonds of one colour commute as Hamiltonian
pieces, so a colour is one exact flow of the spin systems (``jaxsplit.systems.spin_lattice``).

``graph(n_sites, bonds)`` colours any simple graph with at most Δ + 1 colours (Δ the largest
degree; Vizing's bound) by the Misra–Gries algorithm (Misra and Gries, Inf. Process. Lett. 41
(1992) 131): each bond is coloured by rotating a fan of its first endpoint and inverting one
alternating two-colour path. The named lattices (``_lattices``) carry optimal colourings.
"""

import dataclasses

import numpy as np

from ..core._errors import InputError


@dataclasses.dataclass(frozen=True, eq=False)
class Lattice:
    """Sites, bonds and an edge colouring (see the module docstring).

    ``name`` ("chain", ..., or "graph"), ``size`` (cells per axis, () for a graph),
    ``periodic``, ``positions`` (N, d) float, ``bonds`` (B, 2) int (site i, site j), ``shape``
    (the state's shape without its trailing 3: (L,), (Lx, Ly), (Lx, Ly, 2) for the honeycomb's
    two sites per cell, (N,) for a graph), ``colours`` (tuple of int arrays of bond indices,
    each a matching), ``cell`` (d, d) primitive vectors as rows (None for a graph) and
    ``basis`` (s, d) the sites of one cell. Hashable by identity (equal records compare
    equal by content).
    """

    name: str
    size: tuple
    periodic: bool
    positions: np.ndarray
    bonds: np.ndarray
    shape: tuple
    colours: tuple
    cell: np.ndarray | None = None
    basis: np.ndarray | None = None

    @property
    def n_sites(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_bonds(self) -> int:
        return int(self.bonds.shape[0])

    @property
    def dimension(self) -> int:
        return int(self.positions.shape[1])

    @property
    def max_degree(self) -> int:
        return int(np.max(degrees(self.n_sites, self.bonds), initial=0))

    def coloured_bonds(self) -> tuple:
        """The bonds of each colour: (B_c, 2) int arrays."""
        return tuple(self.bonds[c] for c in self.colours)

    def neighbours(self) -> list:
        """Site -> sorted list of its neighbours."""
        out = [[] for _ in range(self.n_sites)]
        for i, j in self.bonds.tolist():
            out[i].append(j)
            out[j].append(i)
        return [sorted(n) for n in out]

    def __eq__(self, other):
        return isinstance(other, Lattice) and (self.name, self.size, self.periodic, self.shape) == (
            other.name, other.size, other.periodic, other.shape) and np.array_equal(self.bonds, other.bonds)

    def __hash__(self):
        return hash((self.name, self.size, self.periodic, self.shape, self.bonds.tobytes()))

    def __repr__(self):
        return (f"Lattice({self.name!r}, size={self.size}, periodic={self.periodic}, n_sites={self.n_sites}, "
                f"n_bonds={self.n_bonds}, colours={len(self.colours)})")


def degrees(n_sites: int, bonds) -> np.ndarray:
    return np.bincount(np.asarray(bonds, dtype=np.int64).reshape(-1), minlength=n_sites)


def check_bonds(n_sites: int, bonds) -> np.ndarray:
    """Bonds as a (B, 2) int64 array of a simple graph on ``n_sites`` sites (one-line errors)."""
    if isinstance(n_sites, bool) or not isinstance(n_sites, (int, np.integer)) or n_sites < 1:
        raise InputError(f"n_sites must be an integer >= 1, got {n_sites!r}")
    arr = np.asarray(bonds)
    if arr.size == 0:
        arr = arr.reshape(0, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InputError(f"bonds must be a (B, 2) array of site pairs, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer) and not (
            np.issubdtype(arr.dtype, np.floating) and np.all(arr == np.round(arr))):
        raise InputError(f"bonds must be integer site indices, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    bad = (arr < 0) | (arr >= n_sites)
    if np.any(bad):
        raise InputError(f"bond site indices must lie in 0..{n_sites - 1}, got {int(arr[bad][0])}")
    loops = arr[:, 0] == arr[:, 1]
    if np.any(loops):
        raise InputError(f"a bond joins site {int(arr[loops][0, 0])} to itself (bond {int(np.argmax(loops))}); "
                         "bonds join two different sites")
    key = np.sort(arr, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        pair = key[first[np.argmax(counts > 1)]].tolist()
        raise InputError(f"the bond {pair} appears {int(counts.max())} times; give each pair once (per-bond "
                         "couplings add up: sum them into one bond)")
    return arr


def is_proper(n_sites: int, bonds, colours) -> bool:
    """Every bond coloured once and each colour a matching."""
    bonds = np.asarray(bonds)
    seen = np.concatenate([np.asarray(c, dtype=np.int64) for c in colours]) if colours else np.zeros(0, np.int64)
    if len(seen) != len(bonds) or np.any(seen < 0) or np.any(np.bincount(seen, minlength=len(bonds)) != 1):
        return False
    return all(np.all(degrees(n_sites, bonds[np.asarray(c, dtype=np.int64)]) <= 1) for c in colours)


def misra_gries(n_sites: int, bonds) -> tuple:
    """A proper edge colouring with at most Δ + 1 colours (module docstring): tuple of arrays of
    bond indices, one per colour (empty colours dropped)."""
    bonds = np.asarray(bonds, dtype=np.int64)
    delta = int(np.max(degrees(n_sites, bonds), initial=0))
    palette = range(delta + 1)
    at = [{} for _ in range(n_sites)]  # site -> {colour: neighbour}
    colour_of = {}  # (min, max) -> colour

    def key(u, v):
        return (u, v) if u < v else (v, u)

    def free(u):
        return next(c for c in palette if c not in at[u])

    def paint(u, v, c):
        at[u][c] = v
        at[v][c] = u
        colour_of[key(u, v)] = c

    def wipe(u, v):
        c = colour_of.pop(key(u, v))
        del at[u][c], at[v][c]
        return c

    neighbours = [[] for _ in range(n_sites)]
    for i, j in bonds.tolist():
        neighbours[i].append(j)
        neighbours[j].append(i)
    for u, v in bonds.tolist():
        fan, in_fan = [v], {v}
        while True:  # a maximal fan of u: each next edge's colour is free at the previous fan vertex
            last = fan[-1]
            nxt = next((w for w in neighbours[u] if w not in in_fan and key(u, w) in colour_of
                        and colour_of[key(u, w)] not in at[last]), None)
            if nxt is None:
                break
            fan.append(nxt)
            in_fan.add(nxt)
        c, d = free(u), free(fan[-1])
        if c != d:  # invert the cd-path from u: d becomes free at u
            path, x, want = [], u, d
            while want in at[x]:
                y = at[x][want]
                path.append((x, y))
                x, want = y, (c if want == d else d)
            olds = [wipe(a, b) for a, b in path]
            for (a, b), old in zip(path, olds):
                paint(a, b, c if old == d else d)
        k = next(k for k, w in enumerate(fan) if d not in at[w])
        shifted = [colour_of[key(u, fan[i + 1])] for i in range(k)]
        for i in range(1, k + 1):
            wipe(u, fan[i])
        for i in range(k):
            paint(u, fan[i], shifted[i])
        paint(u, fan[k], d)
    index = {key(int(i), int(j)): b for b, (i, j) in enumerate(bonds.tolist())}
    groups = [[] for _ in palette]
    for edge, c in colour_of.items():
        groups[c].append(index[edge])
    return tuple(np.array(sorted(g), dtype=np.int64) for g in groups if g)


def graph(n_sites: int, bonds, positions=None) -> Lattice:
    """A user's bond graph as a ``Lattice``: ``bonds`` (B, 2) site pairs (each pair once, no
    self-bonds), coloured by Misra–Gries with at most Δ + 1 colours; ``positions`` (N, d)
    optional (default: the site index on a line).

    >>> import jaxsplit
    >>> g = jaxsplit.lattices.graph(4, [[0, 1], [1, 2], [2, 0], [2, 3]])   # a triangle with a tail
    >>> g.max_degree, len(g.colours)
    (3, 3)
    """
    bonds = check_bonds(n_sites, bonds)
    if positions is None:
        positions = np.arange(n_sites, dtype=float)[:, None]
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 2 or positions.shape[0] != n_sites or not np.all(np.isfinite(positions)):
        raise InputError(f"positions must be a finite ({n_sites}, d) array, got shape {positions.shape}")
    return Lattice("graph", (), False, positions, bonds, (int(n_sites),), misra_gries(n_sites, bonds))
