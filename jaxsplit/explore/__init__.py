"""Exploration on the system layer, each tool taking a family ``params -> system``:
batched sweeps sharded over devices (``_sweep``, on the batch machinery of ``_batch``),
linear stability maps at equilibria (``_stability``), fitting a system's parameters to
observed trajectories (``_fit``; the free body's gauge in ``_fit_inertia``; a spin
lattice's couplings, also to S(q, ω), in ``_fit_spins``), and tuning
composition coefficients with optax (``_tune``)."""

from ._fit import ParameterFit as ParameterFit
from ._fit import fit as fit
from ._fit import simulate as simulate
from ._fit_inertia import FitResult as FitResult
from ._fit_spins import CouplingFit as CouplingFit
from ._fit_spins import fit_couplings as fit_couplings
from ._fit_inertia import fit_inertia as fit_inertia
from ._fit_inertia import simulate_observations as simulate_observations
from ._stability import stability_map as stability_map
from ._sweep import reference_solution as reference_solution
from ._sweep import sweep as sweep
from ._sweep import sweep_cases as sweep_cases
from ._tune import TunedScheme as TunedScheme
from ._tune import order4_coefficients as order4_coefficients
from ._tune import random_bodies as random_bodies
from ._tune import tune_scheme as tune_scheme
