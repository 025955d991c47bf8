"""Systems: a state, a Poisson structure, a Hamiltonian, Casimirs and the splits into exactly
solvable pieces, built from the so(3) toolkit (``so3``).

Modules: ``_base`` (``AbstractSystem``, the protocol a user's own system implements),
``_rigid_body`` (the free body), ``_hamilton_poisson`` (a system from two functions: the
paper's §2–3 examples), ``_splitting`` (``splitting``: system + scheme -> step), ``_auto`` (``auto_splitting``: the
cheapest scheme, split and step for a tolerance), ``so3``
(rotations, quaternions, rotation flows that turn declared parts of a state).
"""

from . import so3 as so3
from ._auto import AutoSplitting as AutoSplitting
from ._auto import auto_splitting as auto_splitting
from ._base import AbstractSystem as AbstractSystem
from ._hamilton_poisson import HamiltonPoisson as HamiltonPoisson
from ._rigid_body import STANDARD_CASE as STANDARD_CASE
from ._rigid_body import RigidBody as RigidBody
from ._rigid_body import symmetric_solution as symmetric_solution
from ._splitting import splitting as splitting


def rigid_body(inertia) -> RigidBody:
    """The free rigid body, state m (3,): splits ``"axes"`` (the paper's three rotations) and
    ``"casimir"`` (two rotations, H − C/I_k)."""
    return RigidBody(inertia)
