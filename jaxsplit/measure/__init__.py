"""Measurements on trajectories: ``structure_factor`` (the dynamical structure factor
S(q, ω) of a spin trajectory on a lattice, ``_structure_factor``)."""

from ._structure_factor import StructureFactor as StructureFactor
from ._structure_factor import structure_factor as structure_factor
