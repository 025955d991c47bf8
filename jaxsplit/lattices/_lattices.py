"""The named lattices: a unit cell (primitive vectors, basis sites, bond types) repeated over a
box, periodic or open, with an optimal edge colouring.

A bond type (a, b, offset) joins basis site a of cell c to basis site b of cell c + offset.
Its bonds are a matching when a ≠ b (honeycomb); when a = b they form cycles along the
offset, split into two matchings by the parity of the cell coordinate along an axis the
offset moves (one step per bond): proper for open boundaries and even periodic lengths.
Hence chain 2, square 4, triangular 6, simple cubic 6 and honeycomb 3 colours: Δ each, the
minimum. A periodic odd length needs Δ + 1 colours (an odd cycle): those lattices are
coloured by Misra–Gries (``_graph``), still at most Δ + 1.

Site index: row-major over (cell coordinates..., basis site), so a state of shape
``lattice.shape + (3,)`` reshapes to (N, 3) without a copy.
"""

import numpy as np

from ..core._errors import InputError
from ._graph import Lattice, is_proper, misra_gries

_S3 = np.sqrt(3.0)

# name -> (primitive vectors (rows), basis sites, bond types (a, b, offset))
UNIT_CELLS = {
    "chain": (np.eye(1), np.zeros((1, 1)), ((0, 0, (1,)),)),
    "square": (np.eye(2), np.zeros((1, 2)), ((0, 0, (1, 0)), (0, 0, (0, 1)))),
    "triangular": (np.array([[1.0, 0.0], [0.5, _S3 / 2]]), np.zeros((1, 2)),
                   ((0, 0, (1, 0)), (0, 0, (0, 1)), (0, 0, (-1, 1)))),
    # bond length 1: B = (a1 + a2)/3, and A(c) joins B(c), B(c − a1), B(c − a2)
    "honeycomb": (np.array([[_S3, 0.0], [_S3 / 2, 1.5]]), np.array([[0.0, 0.0], [_S3 / 2, 0.5]]),
                  ((0, 1, (0, 0)), (0, 1, (-1, 0)), (0, 1, (0, -1)))),
    "simple-cubic": (np.eye(3), np.zeros((1, 3)), ((0, 0, (1, 0, 0)), (0, 0, (0, 1, 0)), (0, 0, (0, 0, 1)))),
}
NAMES = tuple(UNIT_CELLS)
MAX_SITES = 2**27  # 1.3e8 spins: 3 GB of float64 state; beyond it a typo, not a run


def parse_size(name: str, size) -> tuple:
    """Cells per axis as a tuple of ints >= 1 for lattice ``name``: an int (the same on every
    axis), a sequence, or a string "64", "64x64"."""
    d = UNIT_CELLS[name][0].shape[0]
    raw = size
    if isinstance(size, str):
        try:
            size = tuple(int(part) for part in size.lower().split("x"))
        except ValueError:
            raise InputError(f"size must be like 64 or 64x64 (cells per axis), got {raw!r}") from None
    elif isinstance(size, (int, np.integer)) and not isinstance(size, bool):
        size = (int(size),) * d
    else:
        try:
            size = tuple(size)
        except TypeError:
            raise InputError(f"size must be an integer or one integer per axis, got {raw!r}") from None
        if not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in size):
            raise InputError(f"size must hold integers (cells per axis), got {raw!r}")
        size = tuple(int(s) for s in size)
    if len(size) == 1 and d > 1:
        size = size * d
    if len(size) != d:
        raise InputError(f"a {name} lattice has {d} axes: size needs {d} numbers (or one), got {raw!r}")
    if any(s < 1 for s in size):
        raise InputError(f"size must be >= 1 cell per axis, got {raw!r}")
    if np.prod(size, dtype=float) * len(UNIT_CELLS[name][1]) > MAX_SITES:
        raise InputError(f"a {name} lattice of size {'x'.join(map(str, size))} has more than {MAX_SITES} sites")
    return size


def simple(bond_types, lengths, periodic: bool) -> bool:
    """Whether the bonds of ``bond_types`` on a box of ``lengths`` cells form a simple graph (no
    site joined to itself, no pair twice), decided from the offsets alone (the same verdict as
    ``check_bonds`` on the bond list, without sorting 10⁸ bonds: tests/test_spin_lattice.py). Wrapped
    around a periodic box, bond types (a, b, o) and (a', b', o') give the same pair at some cell
    iff o ≡ o' (a = a', b = b') or o ≡ −o' (a = b', b = a') modulo the lengths; a type with
    a = b joins a site to itself iff o ≡ 0 and repeats its own pairs iff 2·o ≡ 0. Open, the
    offsets are distinct and nonzero, so the graph is simple whenever a bond fits in the box."""
    if not periodic:
        return True
    wrap = lambda o: tuple(np.mod(np.asarray(o), lengths))
    for t, (a, b, o) in enumerate(bond_types):
        if a == b and (not any(wrap(o)) or not any(wrap(2 * np.asarray(o)))):
            return False
        for a2, b2, o2 in bond_types[t + 1:]:
            if (a, b) == (a2, b2) and wrap(o) == wrap(o2) or (a, b) == (b2, a2) and wrap(o) == wrap(-np.asarray(o2)):
                return False
    return True


def lattice(name: str, size, periodic: bool = True) -> Lattice:
    """The lattice ``name`` (chain, square, triangular, honeycomb, simple-cubic) of ``size``
    cells per axis, periodic or open, with its optimal edge colouring (module docstring).

    >>> import jaxsplit
    >>> sq = jaxsplit.lattices.lattice("square", (4, 6))
    >>> sq.n_sites, sq.bonds.shape, sq.shape, len(sq.colours)
    (24, (48, 2), (4, 6), 4)
    >>> hc = jaxsplit.lattices.lattice("honeycomb", 3, periodic=False)
    >>> hc.shape, len(hc.colours), hc.max_degree
    ((3, 3, 2), 3, 3)
    """
    if name not in UNIT_CELLS:
        raise InputError(f"unknown lattice {name!r}; choose one of {', '.join(NAMES)} (or jaxsplit.lattices.graph "
                         "for your own bonds)")
    if not isinstance(periodic, (bool, np.bool_)):
        raise InputError(f"periodic must be True or False, got {periodic!r}")
    size = parse_size(name, size)
    cell, basis, bond_types = UNIT_CELLS[name]
    n_basis = len(basis)
    lengths = np.array(size)
    if not simple(bond_types, lengths, periodic):
        need = 3 if n_basis == 1 else 2
        raise InputError(f"a periodic {name} lattice needs at least {need} cells per axis (fewer would join a site "
                         f"to itself or repeat a bond), got size {'x'.join(map(str, size))}; use periodic=False "
                         "or a larger size")
    cells = np.indices(size, dtype=np.int64).reshape(len(size), -1)  # (axes, cells), row-major over the cells
    numbers = np.arange(cells.shape[1])
    # Σ_k c_k a_k by axis: a BLAS product with an inner size of 2 or 3 is slower at 10⁸ cells
    positions = sum(cells[k][:, None] * cell[k] for k in range(len(size)))[:, None, :] + basis[None, :, :]
    bonds, groups = [], []
    for a, b, offset in bond_types:
        target = cells + np.array(offset)[:, None]
        if periodic:
            target %= lengths[:, None]
            source, moved = numbers, cells
        else:  # bonds whose far end leaves the box are not there
            inside = np.all((target >= 0) & (target < lengths[:, None]), axis=0)
            source, moved, target = numbers[inside], cells[:, inside], target[:, inside]
        pairs = np.stack([source * n_basis + a, np.ravel_multi_index(tuple(target), size) * n_basis + b], axis=1)
        start = sum(len(p) for p in bonds)
        bonds.append(pairs)
        if a != b:
            groups.append(np.arange(start, start + len(pairs)))
        else:  # a cycle along the offset: two matchings by parity along an axis it moves
            axis = int(np.flatnonzero(np.array(offset))[0])
            parity = moved[axis] % 2
            groups += [start + np.flatnonzero(parity == p) for p in (0, 1)]
    bonds = np.concatenate(bonds) if bonds else np.zeros((0, 2), np.int64)
    n_sites = len(numbers) * n_basis
    shape = tuple(size) + ((n_basis,) if n_basis > 1 else ())
    colours = tuple(np.asarray(g, dtype=np.int64) for g in groups if len(g))
    if not is_proper(n_sites, bonds, colours):  # a periodic odd length: Δ + 1 colours
        colours = misra_gries(n_sites, bonds)
    return Lattice(name, tuple(size), bool(periodic), positions.reshape(n_sites, -1), bonds, shape, colours,
                   cell.copy(), basis.copy())
