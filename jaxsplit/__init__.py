"""jaxsplit: structure-preserving (Poisson / symplectic) splitting integrators in JAX.

The free rigid body is split into pieces whose flows are exact rotations; composition
schemes stored as data turn those flows into integrators of any even order, stepped by a
``lax.scan`` loop that jits, vmaps and differentiates.

>>> import jax.numpy as jnp, jaxsplit
>>> body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]))
>>> step = jaxsplit.splitting(body, "kahan-li-6", split="casimir")
>>> m10 = jaxsplit.integrate(step, jnp.array([0.45, 0.0, 0.89]), 0.1, 100)
"""

from importlib.metadata import PackageNotFoundError, version

from ._body import PAPER_BODY as PAPER_BODY
from ._body import PAPER_M0 as PAPER_M0
from ._body import STANDARD_CASE as STANDARD_CASE
from ._body import RigidBody as RigidBody
from ._compose import Composition as Composition
from ._compose import compose as compose
from ._errors import InputError as InputError
from ._exact import symmetric_solution as symmetric_solution
from ._integrate import Trajectory as Trajectory
from ._integrate import integrate as integrate
from ._order import OrderFit as OrderFit
from ._order import fit_order as fit_order
from ._order import global_errors as global_errors
from ._order import ladder as ladder
from ._rotations import hat as hat
from ._rotations import rotation_matrix as rotation_matrix
from ._schemes import Scheme as Scheme
from ._schemes import schemes as schemes
from ._schemes import triple_jump as triple_jump
from ._splitting import AxisRotation as AxisRotation
from ._splitting import splitting as splitting
from ._sweep import reference_solution as reference_solution
from ._sweep import sweep as sweep
from ._sweep import sweep_cases as sweep_cases

try:
    __version__ = version("jaxsplit")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
