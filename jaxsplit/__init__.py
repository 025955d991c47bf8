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

from ._audit import audit_paper as audit_paper
from ._body import PAPER_BODY as PAPER_BODY
from ._body import PAPER_M0 as PAPER_M0
from ._body import STANDARD_CASE as STANDARD_CASE
from ._body import RigidBody as RigidBody
from ._compose import Composition as Composition
from ._compose import RolledComposition as RolledComposition
from ._compose import compose as compose
from ._compose import roll as roll
from ._errors import InputError as InputError
from ._exact import symmetric_solution as symmetric_solution
from ._fit import FitResult as FitResult
from ._fit import fit_inertia as fit_inertia
from ._fit import integrate_checkpointed as integrate_checkpointed
from ._fit import simulate_observations as simulate_observations
from ._hamilton_poisson import HamiltonPoisson as HamiltonPoisson
from ._hamilton_poisson import canonical_system as canonical_system
from ._hamilton_poisson import constant_poisson_system as constant_poisson_system
from ._hamilton_poisson import example_3_1 as example_3_1
from ._hamilton_poisson import harmonic_oscillator as harmonic_oscillator
from ._hamilton_poisson import rigid_body_system as rigid_body_system
from ._integrate import Trajectory as Trajectory
from ._integrate import integrate as integrate
from ._invariants import InvariantErrors as InvariantErrors
from ._invariants import invariant_errors as invariant_errors
from ._invariants import monitor_invariants as monitor_invariants
from ._order import OrderFit as OrderFit
from ._order import estimate_order as estimate_order
from ._order import fit_order as fit_order
from ._order import global_errors as global_errors
from ._order import ladder as ladder
from ._poisson_check import DefectSummary as DefectSummary
from ._poisson_check import PoissonSummary as PoissonSummary
from ._poisson_check import defect_summary as defect_summary
from ._poisson_check import growth_exponent as growth_exponent
from ._poisson_check import orbit_symplectic_defect as orbit_symplectic_defect
from ._poisson_check import poisson_defect as poisson_defect
from ._poisson_check import poisson_summary as poisson_summary
from ._poisson_check import symplectic_defect as symplectic_defect
from ._poisson_check import symplectic_summary as symplectic_summary
from ._rotations import hat as hat
from ._rotations import rotate as rotate
from ._rotations import rotation_matrix as rotation_matrix
from ._runge_kutta import ButcherTableau as ButcherTableau
from ._runge_kutta import CoefficientRungeKutta as CoefficientRungeKutta
from ._runge_kutta import RungeKutta as RungeKutta
from ._runge_kutta import explicit_euler as explicit_euler
from ._runge_kutta import gauss_legendre as gauss_legendre
from ._runge_kutta import gauss_legendre_tableau as gauss_legendre_tableau
from ._runge_kutta import rk4 as rk4
from ._runge_kutta import runge_kutta as runge_kutta
from ._runge_kutta import runge_kutta_coefficients as runge_kutta_coefficients
from ._runge_kutta import ruth as ruth
from ._runge_kutta import tableaus as tableaus
from ._runge_kutta import trapezoid as trapezoid
from ._schemes import Scheme as Scheme
from ._schemes import schemes as schemes
from ._schemes import triple_jump as triple_jump
from ._splitting import AxisRotation as AxisRotation
from ._splitting import rigid_body_flows as rigid_body_flows
from ._splitting import splitting as splitting
from ._stability import stability_map as stability_map
from ._sweep import reference_solution as reference_solution
from ._sweep import sweep as sweep
from ._sweep import sweep_cases as sweep_cases
from ._tableau_checks import condition_2_7_defect as condition_2_7_defect
from ._tableau_checks import order_conditions as order_conditions
from ._tableau_checks import rooted_trees as rooted_trees
from ._tableau_checks import symplecticity_matrix as symplecticity_matrix
from ._tableau_checks import tableau_order as tableau_order
from ._tune import TunedScheme as TunedScheme
from ._tune import order4_coefficients as order4_coefficients
from ._tune import random_bodies as random_bodies
from ._tune import tune_scheme as tune_scheme

try:
    __version__ = version("jaxsplit")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
