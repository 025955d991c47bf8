"""Checks of any map and any state: Poisson and symplectic defects by ``jax.jacfwd``
(``_poisson``), the Jacobi identity of a Poisson matrix (``_poisson``), invariant monitors
(``_invariants``), convergence orders (``_order``), and the algebraic conditions of
Runge–Kutta tableaus (``_tableau``)."""

from ._invariants import InvariantErrors as InvariantErrors
from ._invariants import invariant_errors as invariant_errors
from ._invariants import monitor_invariants as monitor_invariants
from ._order import OrderFit as OrderFit
from ._order import estimate_order as estimate_order
from ._order import fit_order as fit_order
from ._order import global_errors as global_errors
from ._order import ladder as ladder
from ._poisson import DefectSummary as DefectSummary
from ._poisson import PoissonSummary as PoissonSummary
from ._poisson import defect_summary as defect_summary
from ._poisson import growth_exponent as growth_exponent
from ._poisson import jacobi_defect as jacobi_defect
from ._poisson import jacobi_summary as jacobi_summary
from ._poisson import orbit_symplectic_defect as orbit_symplectic_defect
from ._poisson import poisson_defect as poisson_defect
from ._poisson import poisson_summary as poisson_summary
from ._poisson import symplectic_defect as symplectic_defect
from ._poisson import symplectic_summary as symplectic_summary
from ._tableau import condition_2_7_defect as condition_2_7_defect
from ._tableau import order_conditions as order_conditions
from ._tableau import rooted_trees as rooted_trees
from ._tableau import symplecticity_matrix as symplecticity_matrix
from ._tableau import tableau_order as tableau_order
