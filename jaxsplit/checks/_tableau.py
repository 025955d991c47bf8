"""Algebraic checks of a Butcher tableau (A, b): condition (2.7) and the order conditions.

* Condition (2.7) of the seed paper (Lasagni 1988, Sanz-Serna 1988, Suris 1989):
  M_ij = b_i a_ij + b_j a_ji − b_i b_j = 0 for all i, j. It makes an RK method symplectic
  for canonical systems, Poisson for constant Π, and conservative of every quadratic
  invariant; for irreducible methods it is also necessary.
* Order conditions (Butcher): the method has order p iff Σ_i b_i Φ_i(t) = 1/γ(t) for every
  rooted tree t with |t| <= p, with Φ_i(τ) = 1 and Φ_i([t_1, …, t_m]) = Π_k (A Φ(t_k))_i
  (so the stage nodes are taken as c = A·1), γ(τ) = 1, γ([t_1..t_m]) = |t| Π γ(t_k).
  There are 1, 1, 2, 4, 9, 20, 48 trees of order 1..7. The issue asks for order <= 4
  (8 conditions); the same code checks any order, which validates GL3's order 6.

Everything here is plain NumPy in float64 on concrete coefficients: tableaus are data.
"""

import functools
import math
from typing import NamedTuple

import numpy as np

from ..core._errors import InputError

CONDITION_TOL = 1e-14  # coefficients are given to ~16 digits
ORDER_TOL = 1e-13


def _coefficients(tableau):
    """(A, b) as float64 arrays from a tableau object or an (A, b) pair."""
    if hasattr(tableau, "a") and hasattr(tableau, "b"):
        a, b = tableau.a, tableau.b
    else:
        try:
            a, b = tableau
        except (TypeError, ValueError) as err:
            raise InputError(f"expected a ButcherTableau or an (A, b) pair, got {tableau!r}") from err
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or b.shape != (a.shape[0],):
        raise InputError(f"A must be s x s and b of length s, got shapes {a.shape} and {b.shape}")
    return a, b


def symplecticity_matrix(tableau) -> np.ndarray:
    """M_ij = b_i a_ij + b_j a_ji − b_i b_j (condition (2.7) is M = 0); NumPy float64 (s, s) for
    an s-stage tableau (a ``ButcherTableau`` or an (A, b) pair).

    >>> import jaxsplit
    >>> jaxsplit.symplecticity_matrix(jaxsplit.tableaus["implicit-midpoint"]).tolist()
    [[0.0]]
    """
    a, b = _coefficients(tableau)
    ba = b[:, None] * a
    return ba + ba.T - np.outer(b, b)


def condition_2_7_defect(tableau) -> float:
    """max_ij |b_i a_ij + b_j a_ji − b_i b_j| (a float): 0 for symplectic RK methods.

    >>> import jaxsplit
    >>> jaxsplit.condition_2_7_defect(jaxsplit.tableaus["gauss-legendre-2"]) < 1e-15
    True
    >>> jaxsplit.condition_2_7_defect(jaxsplit.tableaus["trapezoid"])
    0.25
    """
    return float(np.max(np.abs(symplecticity_matrix(tableau))))


def satisfies_condition_2_7(tableau, tol: float = CONDITION_TOL) -> bool:
    return condition_2_7_defect(tableau) <= tol


# ------------------------------------------------------------------ rooted trees
Tree = tuple  # a rooted tree is the sorted tuple of its children's trees; () is τ


def tree_order(tree: Tree) -> int:
    return 1 + sum(tree_order(t) for t in tree)


def tree_density(tree: Tree) -> int:
    """γ(t) = |t| · Π γ(children)."""
    return tree_order(tree) * math.prod(tree_density(t) for t in tree)


def _key(tree: Tree):
    return (tree_order(tree), tuple(_key(t) for t in tree))


@functools.cache
def rooted_trees(order: int) -> tuple[Tree, ...]:
    """All rooted trees with ``order`` vertices, each once; a tree is the tuple of its children
    (a sorted multiset), τ = ``()``. Cached.

    >>> import jaxsplit
    >>> jaxsplit.rooted_trees(3), [len(jaxsplit.rooted_trees(p)) for p in range(1, 6)]
    ((((), ()), (((),),)), [1, 1, 2, 4, 9])
    """
    if not (isinstance(order, int) and order >= 1):
        raise InputError(f"tree order must be a positive integer, got {order!r}")
    if order == 1:
        return ((),)
    out = []

    def build(remaining, floor, children):
        if remaining == 0:
            out.append(tuple(children))
            return
        for k in range(1, remaining + 1):
            for t in rooted_trees(k):
                if floor is None or _key(t) >= floor:
                    build(remaining - k, _key(t), children + [t])

    build(order - 1, None, [])
    return tuple(out)


def _stage_weights(tree: Tree, a: np.ndarray) -> np.ndarray:
    """Φ_i(t): ones for τ, else the product over children of A Φ(child)."""
    out = np.ones(a.shape[0])
    for child in tree:
        out = out * (a @ _stage_weights(child, a))
    return out


def tree_label(tree: Tree) -> str:
    """Butcher's bracket notation: τ, [τ], [τ,τ], [[τ]], …"""
    return "τ" if not tree else "[" + ",".join(tree_label(t) for t in tree) + "]"


class OrderCondition(NamedTuple):
    tree: str
    order: int
    residual: float  # Σ b_i Φ_i(t) − 1/γ(t)


def order_conditions(tableau, max_order: int = 4) -> tuple[OrderCondition, ...]:
    """Residuals of every order condition of order <= ``max_order`` (default 4: 8 trees): a
    tuple of ``(tree, order, residual)`` records, residual = Σ b_i Φ_i(t) − 1/γ(t) (float64).

    >>> import jaxsplit
    >>> [(c.tree, c.order) for c in jaxsplit.order_conditions(jaxsplit.tableaus["rk4"], 3)]
    [('τ', 1), ('[τ]', 2), ('[τ,τ]', 3), ('[[τ]]', 3)]
    """
    a, b = _coefficients(tableau)
    rows = []
    for p in range(1, max_order + 1):
        for t in rooted_trees(p):
            rows.append(OrderCondition(tree_label(t), p, float(b @ _stage_weights(t, a) - 1.0 / tree_density(t))))
    return tuple(rows)


def tableau_order(tableau, max_order: int = 4, tol: float = ORDER_TOL) -> int:
    """The largest p <= ``max_order`` with every condition of order <= p satisfied to ``tol`` (an int).

    >>> import jaxsplit
    >>> jaxsplit.tableau_order(jaxsplit.tableaus["rk4"]), jaxsplit.tableau_order(jaxsplit.tableaus["gauss-legendre-3"], 7)
    (4, 6)
    """
    p = 0
    for cond in order_conditions(tableau, max_order):
        if abs(cond.residual) > tol:
            return cond.order - 1
        p = cond.order
    return p


def is_explicit(tableau) -> bool:
    a, _ = _coefficients(tableau)
    return bool(np.all(np.triu(a) == 0))
