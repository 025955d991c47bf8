"""Algebraic tableau checks: condition (2.7) and the Butcher order conditions.

Each check has a must-pass and a must-fail case; the expected orders are textbook values
(Hairer–Nørsett–Wanner I, II.1–II.7), the tree counts OEIS A000081.
"""

import numpy as np
import pytest

import jaxsplit
from jaxsplit.checks._tableau import (
    condition_2_7_defect,
    is_explicit,
    order_conditions,
    rooted_trees,
    satisfies_condition_2_7,
    symplecticity_matrix,
    tableau_order,
    tree_density,
)
from jaxsplit.classical._runge_kutta import ButcherTableau, gauss_legendre_tableau, tableaus

CONDITION_TOL = 1e-14  # (2.7) on coefficients given to 16 digits
VIOLATION_FLOOR = 1e-3  # methods that violate (2.7) do so by O(1) amounts
ORDER_TOL = 1e-13

# A000081: rooted trees with n nodes.
TREE_COUNTS = (1, 1, 2, 4, 9, 20, 48)

SATISFY_2_7 = ("implicit-midpoint", "gauss-legendre-2", "gauss-legendre-3", "midpoint-composition-2")
VIOLATE_2_7 = ("explicit-euler", "implicit-euler", "trapezoid", "rk4", "radau-iia-2", "lobatto-iiia-3")
KNOWN_ORDERS = {"explicit-euler": 1, "implicit-euler": 1, "trapezoid": 2, "rk4": 4, "radau-iia-2": 3,
                "lobatto-iiia-3": 4, "implicit-midpoint": 2, "gauss-legendre-2": 4, "gauss-legendre-3": 6,
                "midpoint-composition-2": 2, "modified-euler-as-printed": 0}

KUTTA_38 = ((0, 0, 0, 0), (1 / 3, 0, 0, 0), (-1 / 3, 1, 0, 0), (1, -1, 1, 0)), (1 / 8, 3 / 8, 3 / 8, 1 / 8)


def test_rooted_tree_counts_and_densities():
    assert tuple(len(rooted_trees(p)) for p in range(1, 8)) == TREE_COUNTS
    # γ of the bushy tree [τ,τ,τ] is 4, of the tall tree [[[τ]]] is 24.
    assert sorted(tree_density(t) for t in rooted_trees(4)) == [4, 8, 12, 24]


@pytest.mark.parametrize("name", SATISFY_2_7)
def test_condition_2_7_holds(name):
    assert condition_2_7_defect(tableaus[name]) <= CONDITION_TOL
    assert satisfies_condition_2_7(tableaus[name])


@pytest.mark.parametrize("name", VIOLATE_2_7)
def test_condition_2_7_fails(name):
    assert condition_2_7_defect(tableaus[name]) >= VIOLATION_FLOOR
    assert not satisfies_condition_2_7(tableaus[name])


def test_symplecticity_matrix_is_symmetric_and_matches_formula():
    a, b = np.array(KUTTA_38[0], float), np.array(KUTTA_38[1])
    m = symplecticity_matrix(KUTTA_38)
    assert np.allclose(m, m.T, atol=0)
    assert m[1, 2] == pytest.approx(b[1] * a[1, 2] + b[2] * a[2, 1] - b[1] * b[2], abs=1e-16)


@pytest.mark.parametrize("name", sorted(KNOWN_ORDERS))
def test_measured_order_matches_textbook(name):
    assert tableau_order(tableaus[name], max_order=7) == KNOWN_ORDERS[name]


def test_gauss_legendre_order_2s_any_s():
    for s in range(1, 5):
        assert tableau_order(gauss_legendre_tableau(s), max_order=8, tol=1e-12) == 2 * s
        assert condition_2_7_defect(gauss_legendre_tableau(s)) <= 1e-14


def test_order_conditions_pass_and_fail():
    assert tableau_order(KUTTA_38) == 4
    assert all(abs(c.residual) <= ORDER_TOL for c in order_conditions(KUTTA_38))
    # perturbing one weight (keeping sum b = 1) must break order 2 and beyond
    a = KUTTA_38[0]
    bad = (a, (1 / 8 + 0.01, 3 / 8 - 0.01, 3 / 8, 1 / 8))
    assert tableau_order(bad) == 1
    assert next(c.order for c in order_conditions(bad) if abs(c.residual) > ORDER_TOL) == 2
    assert len(order_conditions(KUTTA_38)) == 8


def test_declared_order_is_validated():
    with pytest.raises(jaxsplit.InputError, match="declared order"):
        ButcherTableau("fake-rk4", KUTTA_38[0], (0.25, 0.25, 0.25, 0.25), 4)
    with pytest.raises(jaxsplit.InputError, match="row sums"):
        ButcherTableau("bad-c", ((0.0,),), (1.0,), 1, c=(0.5,))
    with pytest.raises(jaxsplit.InputError, match="s x s"):
        ButcherTableau("bad-shape", ((0.0, 1.0),), (1.0,), 1)
    assert is_explicit(tableaus["rk4"]) and not is_explicit(tableaus["gauss-legendre-2"])
    assert tableaus["rk4"].explicit and not tableaus["trapezoid"].explicit
