"""Lattices and bond graphs: sites, bonds and edge colourings (geometry only; the spin
dynamics lives in ``jaxsplit.systems.spin_lattice``).

Modules: ``_graph`` (the ``Lattice`` record, ``graph`` for any bond list, the Misra–Gries
colouring with at most Δ + 1 colours), ``_lattices`` (``lattice``: chain, square,
triangular, honeycomb and simple cubic, periodic or open, with optimal colourings).
"""

from ._graph import Lattice as Lattice
from ._graph import graph as graph
from ._lattices import NAMES as NAMES
from ._lattices import lattice as lattice
