"""Systems: a state, a Poisson structure, a Hamiltonian, Casimirs and the splits into exactly
solvable pieces, built from the so(3) toolkit (``so3``).

Modules: ``_base`` (``AbstractSystem``, the protocol a user's own system implements),
``_rigid_body`` (the free body), ``_attitude`` (the free body with its attitude (m, Q) or
(m, q)), ``_potential`` (a body about a fixed point in a potential of Γ, state (m, Γ); the
potential kick) with ``_heavy_top`` and ``_gravity_gradient``, ``_exact`` (the free body's
exact solution for any inertia, on the JAX elliptic functions of ``_elliptic``), ``_spin``
(rotations by a vanishing angle vector, the spin about m, commuting pieces),
``_hamilton_poisson`` (a system from two functions: the paper's §2–3 examples),
``_splitting`` (``splitting``: system + scheme -> step), ``_auto`` (``auto_splitting``: the
cheapest scheme, split and step for a tolerance), ``_validate`` (one-line errors for bad
concrete parameters and states: ``check_state`` of the spinning-body systems), ``so3``
(rotations, quaternions, rotation flows that turn declared parts of a state), ``_spin_lattice``
(classical spins on a lattice or bond graph, split into the exact bond and site flows of
``_spin_flows``) with the baselines of ``_spin_integrators`` (spherical midpoint, Heun), the thermal
dynamics of ``_spin_langevin`` (stochastic LLG by exact rotations) and the Metropolis sampler
of ``_spin_metropolis``.
"""

from . import so3 as so3
from ._attitude import Attitude as Attitude
from ._attitude import attitude as attitude
from ._auto import AutoSplitting as AutoSplitting
from ._auto import auto_splitting as auto_splitting
from ._base import AbstractSystem as AbstractSystem
from ._exact import exact_solution as exact_solution
from ._gravity_gradient import GravityGradient as GravityGradient
from ._gravity_gradient import gravity_gradient as gravity_gradient
from ._hamilton_poisson import HamiltonPoisson as HamiltonPoisson
from ._heavy_top import HeavyTop as HeavyTop
from ._heavy_top import heavy_top as heavy_top
from ._potential import BodyInPotential as BodyInPotential
from ._potential import PotentialKick as PotentialKick
from ._rigid_body import STANDARD_CASE as STANDARD_CASE
from ._rigid_body import RigidBody as RigidBody
from ._rigid_body import symmetric_solution as symmetric_solution
from ._spin import Commuting as Commuting
from ._spin import MomentumSpin as MomentumSpin
from ._spin_integrators import heun as heun
from ._spin_integrators import spherical_midpoint as spherical_midpoint
from ._spin_langevin import Langevin as Langevin
from ._spin_langevin import langevin as langevin
from ._spin_lattice import SpinLattice as SpinLattice
from ._spin_lattice import spin_lattice as spin_lattice
from ._spin_metropolis import MonteCarlo as MonteCarlo
from ._spin_metropolis import metropolis as metropolis
from ._splitting import splitting as splitting


def rigid_body(inertia, *, allow_nonphysical: bool = False) -> RigidBody:
    """The free rigid body, state m (3,): splits ``"axes"`` (the paper's three rotations) and
    ``"casimir"`` (two rotations, H − C/I_k). ``allow_nonphysical`` as for ``RigidBody``."""
    return RigidBody(inertia, allow_nonphysical)
