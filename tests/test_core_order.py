"""Acceptance 1 (core): every scheme's measured order is within 0.3 of its nominal order,
for every split it applies to, against the exact symmetric solution and against the
30-digit reference value of the asymmetric standard case.

The order is the log-log regression slope of the global error at T = 10 over a ladder of
12 step counts (factor 16 overall), fitted over the asymptotic regime: errors inside
``ORDER_WINDOW`` (about 10x above the round-off floor, below 1e-4) and step sizes whose
largest sub-step |w| h is at most ``ASYMPTOTIC_SUBSTEP`` (the problem's time scale is ~1;
the triple jumps' sub-steps are up to 2.8 h).

The order is the map's: each scheme's word runs rolled (``roll``: the word as data), so a case
compiles a program whose size does not grow with the word, and the two problems of a scheme
share it (the unrolled program of a 10th-order word took ~5 s to compile, per problem). The
unrolled, merged stepper users run is the same map to 1e-12 (test_core_stepper.py's
``test_merged_and_unmerged_compositions_agree``); measured orders of both forms agree within
0.04 on every case.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.checks._order import ORDER_WINDOW

ORDER_TOL = 0.3
ASYMPTOTIC_SUBSTEP = 0.5
T_END = 10.0
# Ladder by nominal order: (smallest first step count, overall factor, points). The ladder starts
# no earlier than where the largest sub-step is ASYMPTOTIC_SUBSTEP.
LADDER = {1: (2000, 16, 12), 2: (200, 16, 12), 4: (30, 16, 12), 6: (20, 16, 12), 8: (12, 8, 12), 10: (8, 4, 24)}

# A symmetric body of the paper's kind (I1 = I2 > I3). On the paper body (2, 2, 1) with
# m0 = (0.6, 0, 0.8) Kahan-Li 10 on the axes split measures ~11.9: its h^10 error term is
# accidentally tiny there and float64 round-off (~1e-14) arrives before it dominates.
SYMMETRIC = jaxsplit.RigidBody(jnp.asarray([3.0, 3.0, 1.0]))
SYMMETRIC_M0 = jnp.asarray([0.6, 0.0, 0.8])
STANDARD = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
STANDARD_M0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)

# The Casimir split shifts by axis 3 (as in shared/reference/coefficients.md): for I1 = I2
# the automatic shift is exact (no splitting error at all), and on the standard case its
# errors are so small that order-10 schemes reach round-off within a factor 2 of h.
# The automatic shift is tested separately (test_core_stepper.py).
PROBLEMS = {
    "symmetric-exact": (SYMMETRIC, SYMMETRIC_M0, {"shift": 2},
                        jaxsplit.symmetric_solution(SYMMETRIC, SYMMETRIC_M0, T_END)),
    "standard-reference": (STANDARD, STANDARD_M0, {"shift": 2},
                           jnp.asarray(jaxsplit.STANDARD_CASE.reference)),
}

# Measurement limit, kept visible: on the Casimir split of the standard case the order-10
# schemes go from the pre-asymptotic regime straight to float64 round-off (~5e-15) within a
# factor ~2 of h. Measured 9.55 (Kahan-Li 10) and 10.65 (Sofroniou-Spaletta 10, whose tuned
# coefficients make the h^10 term small: local slopes fall from 11 towards 10 as h shrinks).
# Both measure within 0.3 of 10 in their three other configurations. strict: a change of
# behaviour in either direction is reported.
# Blanes–Casas–Murua 8 (processed) measures 9.64 there: in 40-digit arithmetic (mpmath, the same
# word, the exact I and m0, the 20-digit reference) its local slopes fall 9.65, 9.20, 8.74, 8.39,
# 8.28 from h = 0.31 to 0.05 (errors 9.4e-12 to 1.2e-18), so order 8 arrives below 1e-15.
UNRESOLVABLE_IN_FLOAT64 = {
    ("kahan-li-10", "casimir", "standard-reference"),
    ("sofroniou-spaletta-10", "casimir", "standard-reference"),
    ("blanes-casas-murua-8", "casimir", "standard-reference"),
}

XFAIL = pytest.mark.xfail(strict=True, reason="asymptotic regime below float64 round-off here")
# a scheme's two problems run one compiled program: on one xdist worker (``--dist loadgroup``)
CASES = [
    pytest.param(name, split, problem, marks=[pytest.mark.xdist_group(f"order-{name}-{split}")]
                 + ([XFAIL] if (name, split, problem) in UNRESOLVABLE_IN_FLOAT64 else []))
    for name in jaxsplit.schemes
    for split, pieces in (("axes", 3), ("casimir", 2))
    if jaxsplit.schemes[name].pieces_allowed(pieces)
    for problem in PROBLEMS
]


@pytest.mark.parametrize("name,split,problem", CASES)
def test_measured_order_matches_nominal(name, split, problem):
    scheme = jaxsplit.schemes[name]
    body, m0, options, reference = PROBLEMS[problem]
    step = jaxsplit.splitting(body, scheme, split, **(options if split == "casimir" else {}))
    largest_weight = max(abs(w) for _, w in step.word)
    max_step = ASYMPTOTIC_SUBSTEP / largest_weight
    smallest_start, factor, points = LADDER[scheme.order]
    counts = jaxsplit.ladder(max(smallest_start, int(np.ceil(T_END / max_step))), factor, points)
    hs, errors = jaxsplit.global_errors(jaxsplit.roll(step), m0, T_END, counts, reference)
    fit = jaxsplit.fit_order(hs, errors, ORDER_WINDOW, max_step=max_step)
    assert abs(fit.order - scheme.order) <= ORDER_TOL, (
        f"{name}/{split}/{problem}: measured order {fit.order:.2f}, nominal {scheme.order}; "
        f"errors {np.array2string(errors, formatter={'float_kind': lambda v: f'{v:.2e}'})}"
    )


def test_order_fit_detects_a_wrong_order():
    """The regression is not a rubber stamp: Strang measured as if it were order 4 fails."""
    step = jaxsplit.splitting(STANDARD, "strang")
    hs, errors = jaxsplit.global_errors(step, STANDARD_M0, T_END, jaxsplit.ladder(200),
                                        PROBLEMS["standard-reference"][3])
    assert abs(jaxsplit.fit_order(hs, errors).order - 4) > ORDER_TOL


def test_the_refusal_prints_small_errors_readably():
    """Issue 31: errors of 1e-3 printed as ``[0. 0. 0. 0.]`` (NumPy's fixed notation at precision 2)."""
    with pytest.raises(jaxsplit.InputError, match=r"errors were \[2\.17e-03 1\.39e-03 8\.73e-04 5\.41e-04\]"):
        jaxsplit.fit_order([0.25, 0.2, 0.16, 0.125], [2.17e-3, 1.39e-3, 8.73e-4, 5.41e-4])


def test_triple_jump_of_any_even_order_resolves_by_name():
    scheme = jaxsplit.schemes["triple-jump-12"]
    assert (scheme.order, scheme.stages) == (12, 3**5)
