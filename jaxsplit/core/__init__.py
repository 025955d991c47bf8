"""The engine every system shares: schemes (data) → compose (flows into a step) → integrate
(the ``lax.scan`` stepper), on states that are any PyTree.

Modules: ``_schemes`` (Scheme, the registry), ``_flows`` (the flow abstraction),
``_compose`` (the composer, Composition, roll), ``_integrate`` (integrate, Trajectory,
checkpointed integration), ``_state`` (what the engine needs of a PyTree state),
``_errors`` (InputError).
"""

from ._compose import Composition as Composition
from ._compose import RolledComposition as RolledComposition
from ._compose import compose as compose
from ._compose import roll as roll
from ._errors import InputError as InputError
from ._flows import AbstractFlow as AbstractFlow
from ._flows import AbstractKick as AbstractKick
from ._flows import FunctionFlow as FunctionFlow
from ._flows import Renormalized as Renormalized
from ._flows import Substeps as Substeps
from ._integrate import Solution as Solution
from ._integrate import Trajectory as Trajectory
from ._integrate import integrate as integrate
from ._integrate import integrate_checkpointed as integrate_checkpointed
from ._schemes import Scheme as Scheme
from ._schemes import schemes as schemes
from ._schemes import triple_jump as triple_jump
