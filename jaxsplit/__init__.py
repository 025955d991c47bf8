"""jaxsplit: structure-preserving (Poisson / symplectic) splitting integrators in JAX.

A system (``systems``: the free rigid body, or your own) declares its state, Poisson
structure, Hamiltonian, Casimirs and its splits into pieces with exact flows; a scheme
stored as data (``core.schemes``) composes those flows into one step (``core.compose``),
which the ``lax.scan`` stepper (``core.integrate``) runs under jit, vmap and grad. The
checks (``checks``) verify any map and any state; ``explore`` sweeps, maps stability,
fits and tunes; ``paper`` audits the seed paper; ``cli`` is the command line.

>>> import jax.numpy as jnp, jaxsplit
>>> body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]))
>>> step = jaxsplit.splitting(body, "kahan-li-6", split="casimir")
>>> m10 = jaxsplit.integrate(step, jnp.array([0.45, 0.0, 0.89]), 0.1, 100)
"""

# The package loads lazily (PEP 562): ``import jaxsplit`` costs microseconds and starts no
# JAX; the first public name asked for loads them all. The command line relies on it: its
# signal policy is installed before JAX is imported (an interrupt there exits 130 cleanly).
import importlib
from importlib.metadata import PackageNotFoundError, version

PUBLIC = {  # module (relative to the package) -> the public names it defines
    "checks._invariants": ("InvariantErrors", "invariant_errors", "monitor_invariants"),
    "checks._order": ("OrderFit", "estimate_order", "fit_order", "global_errors", "ladder"),
    "checks._poisson": (
        "DefectSummary", "PoissonSummary", "defect_summary", "growth_exponent", "jacobi_defect",
        "jacobi_summary", "orbit_symplectic_defect", "poisson_defect", "poisson_summary",
        "symplectic_defect", "symplectic_summary",
    ),
    "checks._tableau": (
        "condition_2_7_defect", "order_conditions", "rooted_trees", "symplecticity_matrix", "tableau_order",
    ),
    "classical._runge_kutta": (
        "ButcherTableau", "CoefficientRungeKutta", "RungeKutta", "explicit_euler", "gauss_legendre",
        "gauss_legendre_tableau", "rk4", "runge_kutta", "runge_kutta_coefficients", "tableaus", "trapezoid",
    ),
    "classical._ruth": ("ruth",),
    "core._compose": ("Composition", "RolledComposition", "compose", "roll"),
    "core._errors": ("InputError",),
    "core._flows": ("AbstractFlow", "FunctionFlow", "Renormalized", "Substeps"),
    "core._integrate": ("Solution", "Trajectory", "integrate", "integrate_checkpointed"),
    "core._schemes": ("Scheme", "schemes", "triple_jump"),
    "explore._fit": ("ParameterFit", "fit", "simulate"),
    "explore._fit_inertia": ("FitResult", "fit_inertia", "simulate_observations"),
    "explore._stability": ("stability_map",),
    "explore._sweep": ("reference_solution", "sweep", "sweep_cases"),
    "explore._tune": ("TunedScheme", "order4_coefficients", "random_bodies", "tune_scheme"),
    "paper": ("audit_paper",),
    "systems._attitude": ("Attitude", "attitude"),
    "systems._base": ("AbstractSystem",),
    "systems._exact": ("exact_solution",),
    "systems._gravity_gradient": ("GravityGradient", "gravity_gradient"),
    "systems._hamilton_poisson": (
        "HamiltonPoisson", "canonical_system", "constant_poisson_system", "example_3_1",
        "harmonic_oscillator", "rigid_body_system",
    ),
    "systems._heavy_top": ("HeavyTop", "heavy_top"),
    "systems._rigid_body": ("PAPER_BODY", "PAPER_M0", "STANDARD_CASE", "RigidBody", "symmetric_solution"),
    "systems._splitting": ("splitting",),
    "systems.so3": (
        "AxisRotation", "VectorRotation", "hat", "quaternion_multiply", "quaternion_to_matrix", "rotate",
        "rotate_about", "rotation_matrix", "rotation_matrix_about",
    ),
}
SUBPACKAGES = ("systems", "core", "checks", "classical", "explore", "paper", "cli")
__all__ = [name for names in PUBLIC.values() for name in names]


def _load_public_names() -> None:
    for module, names in PUBLIC.items():
        loaded = importlib.import_module(f".{module}", __name__)
        globals().update({name: getattr(loaded, name) for name in names})


def __getattr__(name: str):
    if name in SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    if name in __all__:
        _load_public_names()
        return globals()[name]
    raise AttributeError(f"module 'jaxsplit' has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), *__all__, *SUBPACKAGES})


try:
    __version__ = version("jaxsplit")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
