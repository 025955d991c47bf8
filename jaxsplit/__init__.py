"""jaxsplit: structure-preserving (Poisson / symplectic) splitting integrators in JAX.

A system (``systems``: the free rigid body, or your own) declares its state, Poisson
structure, Hamiltonian, Casimirs and its splits into pieces with exact flows; a scheme
stored as data (``core.schemes``) composes those flows into one step (``core.compose``),
which the ``lax.scan`` stepper (``core.integrate``) runs under jit, vmap and grad. The
checks (``checks``) verify any map and any state; ``explore`` sweeps, maps stability,
fits and tunes; ``paper`` audits the seed paper; ``cli`` is the command line.

>>> import jax.numpy as jnp, jaxsplit
>>> body = jaxsplit.STANDARD_CASE.body()    # (2, 1, 2/3): the literature's body, non-physical on purpose
>>> step = jaxsplit.splitting(body, "kahan-li-6", split="casimir")
>>> m10 = jaxsplit.integrate(step, jnp.array([0.45, 0.0, 0.89]), 0.1, 100)
"""

# The package loads lazily (PEP 562): ``import jaxsplit`` costs a millisecond and starts no
# JAX; each public name loads its module on first use. The command line relies on it: its
# signal policy is installed before JAX is imported (an interrupt there exits 130 cleanly).
# The imports below are the one list of public names: type checkers and the documentation
# read them statically, ``__getattr__`` reads them at run time.
import importlib
import typing
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

if typing.TYPE_CHECKING:
    from . import lattices as lattices
    from . import systems as systems
    from ._native import native_status as native_status
    from ._xla_cpu import compiler_options as compiler_options
    from ._xla_cpu import tune_cpu as tune_cpu
    from .checks._invariants import InvariantErrors as InvariantErrors
    from .checks._invariants import invariant_errors as invariant_errors
    from .checks._invariants import monitor_invariants as monitor_invariants
    from .checks._order import OrderFit as OrderFit
    from .checks._order import estimate_order as estimate_order
    from .checks._order import fit_order as fit_order
    from .checks._order import global_errors as global_errors
    from .checks._order import ladder as ladder
    from .checks._poisson import DefectSummary as DefectSummary
    from .checks._poisson import PoissonSummary as PoissonSummary
    from .checks._poisson import defect_summary as defect_summary
    from .checks._poisson import growth_exponent as growth_exponent
    from .checks._poisson import jacobi_defect as jacobi_defect
    from .checks._poisson import jacobi_summary as jacobi_summary
    from .checks._poisson import orbit_symplectic_defect as orbit_symplectic_defect
    from .checks._poisson import poisson_defect as poisson_defect
    from .checks._poisson import poisson_summary as poisson_summary
    from .checks._poisson import symplectic_defect as symplectic_defect
    from .checks._poisson import symplectic_summary as symplectic_summary
    from .checks._tableau import condition_2_7_defect as condition_2_7_defect
    from .checks._tableau import order_conditions as order_conditions
    from .checks._tableau import rooted_trees as rooted_trees
    from .checks._tableau import symplecticity_matrix as symplecticity_matrix
    from .checks._tableau import tableau_order as tableau_order
    from .classical._runge_kutta import ButcherTableau as ButcherTableau
    from .classical._runge_kutta import CoefficientRungeKutta as CoefficientRungeKutta
    from .classical._runge_kutta import RungeKutta as RungeKutta
    from .classical._runge_kutta import explicit_euler as explicit_euler
    from .classical._runge_kutta import gauss_legendre as gauss_legendre
    from .classical._runge_kutta import gauss_legendre_tableau as gauss_legendre_tableau
    from .classical._runge_kutta import rk4 as rk4
    from .classical._runge_kutta import runge_kutta as runge_kutta
    from .classical._runge_kutta import runge_kutta_coefficients as runge_kutta_coefficients
    from .classical._runge_kutta import tableaus as tableaus
    from .classical._runge_kutta import trapezoid as trapezoid
    from .classical._ruth import ruth as ruth
    from .core._compose import Composition as Composition
    from .core._compose import RolledComposition as RolledComposition
    from .core._compose import compose as compose
    from .core._compose import roll as roll
    from .core._errors import InputError as InputError
    from .core._flows import AbstractFlow as AbstractFlow
    from .core._flows import AbstractKick as AbstractKick
    from .core._flows import FunctionFlow as FunctionFlow
    from .core._flows import Renormalized as Renormalized
    from .core._flows import Substeps as Substeps
    from .core._integrate import Solution as Solution
    from .core._integrate import Trajectory as Trajectory
    from .core._integrate import integrate as integrate
    from .core._integrate import integrate_checkpointed as integrate_checkpointed
    from .core._schemes import Scheme as Scheme
    from .core._schemes import schemes as schemes
    from .core._schemes import triple_jump as triple_jump
    from .explore._fit import ParameterFit as ParameterFit
    from .explore._fit import fit as fit
    from .explore._fit import simulate as simulate
    from .explore._fit_spins import CouplingFit as CouplingFit
    from .explore._fit_spins import fit_couplings as fit_couplings
    from .explore._fit_inertia import FitResult as FitResult
    from .explore._fit_inertia import fit_inertia as fit_inertia
    from .explore._fit_inertia import simulate_observations as simulate_observations
    from .explore._stability import stability_map as stability_map
    from .explore._sweep import reference_solution as reference_solution
    from .explore._sweep import sweep as sweep
    from .explore._sweep import sweep_cases as sweep_cases
    from .explore._tune import TunedScheme as TunedScheme
    from .explore._tune import order4_coefficients as order4_coefficients
    from .explore._tune import random_bodies as random_bodies
    from .explore._tune import tune_scheme as tune_scheme
    from .measure._structure_factor import StructureFactor as StructureFactor
    from .measure._structure_factor import structure_factor as structure_factor
    from .paper import audit_paper as audit_paper
    from .systems._attitude import Attitude as Attitude
    from .systems._attitude import attitude as attitude
    from .systems._auto import AutoSplitting as AutoSplitting
    from .systems._auto import auto_splitting as auto_splitting
    from .systems._base import AbstractSystem as AbstractSystem
    from .systems._exact import exact_solution as exact_solution
    from .systems._gravity_gradient import GravityGradient as GravityGradient
    from .systems._gravity_gradient import gravity_gradient as gravity_gradient
    from .systems._hamilton_poisson import HamiltonPoisson as HamiltonPoisson
    from .systems._hamilton_poisson import canonical_system as canonical_system
    from .systems._hamilton_poisson import constant_poisson_system as constant_poisson_system
    from .systems._hamilton_poisson import example_3_1 as example_3_1
    from .systems._hamilton_poisson import harmonic_oscillator as harmonic_oscillator
    from .systems._hamilton_poisson import rigid_body_system as rigid_body_system
    from .systems._heavy_top import HeavyTop as HeavyTop
    from .systems._heavy_top import heavy_top as heavy_top
    from .systems._rigid_body import PAPER_BODY as PAPER_BODY
    from .systems._rigid_body import PAPER_M0 as PAPER_M0
    from .systems._rigid_body import STANDARD_CASE as STANDARD_CASE
    from .systems._rigid_body import RigidBody as RigidBody
    from .systems._rigid_body import symmetric_solution as symmetric_solution
    from .systems._spin_integrators import heun as heun
    from .systems._spin_integrators import spherical_midpoint as spherical_midpoint
    from .systems._spin_langevin import Langevin as Langevin
    from .systems._spin_langevin import langevin as langevin
    from .systems._spin_lattice import SpinLattice as SpinLattice
    from .systems._spin_lattice import spin_lattice as spin_lattice
    from .systems._spin_metropolis import MonteCarlo as MonteCarlo
    from .systems._spin_metropolis import metropolis as metropolis
    from .systems._splitting import splitting as splitting
    from .systems.so3 import AxisRotation as AxisRotation
    from .systems.so3 import VectorRotation as VectorRotation
    from .systems.so3 import hat as hat
    from .systems.so3 import quaternion_multiply as quaternion_multiply
    from .systems.so3 import quaternion_to_matrix as quaternion_to_matrix
    from .systems.so3 import rotate as rotate
    from .systems.so3 import rotate_about as rotate_about
    from .systems.so3 import rotation_matrix as rotation_matrix
    from .systems.so3 import rotation_matrix_about as rotation_matrix_about

_PUBLIC: dict[str, str] | None = None  # name -> defining module ("" for a subpackage)


def _public() -> dict[str, str]:
    global _PUBLIC
    if _PUBLIC is None:
        import ast

        block = next(node for node in ast.parse(Path(__file__).read_text()).body if isinstance(node, ast.If))
        _PUBLIC = {alias.asname or alias.name: node.module or "" for node in block.body for alias in node.names}
    return _PUBLIC


def __getattr__(name: str):
    if name == "__all__":
        return list(_public())
    if name in _public():
        module = importlib.import_module(f".{_public()[name] or name}", __name__)
        value = module if not _public()[name] else getattr(module, name)
    elif (Path(__file__).parent / name / "__init__.py").exists():  # a subpackage: jaxsplit.core, ...
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'jaxsplit' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *_public()})


try:
    __version__ = version("jaxsplit")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
