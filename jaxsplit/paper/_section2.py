"""Claims of §2 of the seed paper (numerical and symplectic integrators): the modified Euler
rule (2.5), Example 2.1 (the Ruth map), Propositions 2.1–2.2 (Gauss–Legendre, condition (2.7)).

Also owns the Runge–Kutta table (``rk_tables``: (2.7), symplecticity on a canonical system and
Poisson property for a constant Π, per tableau) that §3's Propositions 3.1–3.2 read as well.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..checks._order import global_errors
from ..checks._poisson import poisson_defect, random_unit_states, symplectic_defect
from ..checks._tableau import condition_2_7_defect
from ..classical._runge_kutta import padded_coefficients, runge_kutta, runge_kutta_coefficients, tableaus
from ..classical._ruth import Ruth
from ..systems._hamilton_poisson import canonical_system, constant_poisson_system, harmonic_oscillator
from ..systems._rigid_body import PAPER_M0, symmetric_solution
from ._measure import H_RANGE, N_SAMPLES, log_steps, max_defect, paper_body, samples
from ._records import INVARIANT_FLOOR, holds, record


# Hamiltonians for the canonical / constant-Π propositions: genuinely nonlinear.
def _henon_heiles(x):
    q1, q2, p1, p2 = x
    return 0.5 * (p1**2 + p2**2 + q1**2 + q2**2) + q1**2 * q2 - q2**3 / 3


def _cubic_energy(x):
    return 0.5 * (x[0] ** 2 + 2 * x[1] ** 2 + 3 * x[2] ** 2) + x[0] * x[1] * x[2]


_CONSTANT_PI = ((0.0, -3.0, 2.0), (3.0, 0.0, -1.0), (-2.0, 1.0, 0.0))  # hat((1, 2, 3)): degenerate
_SATISFY = ("implicit-midpoint", "gauss-legendre-2", "gauss-legendre-3", "midpoint-composition-2")
_VIOLATE = ("explicit-euler", "implicit-euler", "trapezoid", "rk4", "radau-iia-2", "lobatto-iiia-3")
GAUSS_LEGENDRE = ("implicit-midpoint", "gauss-legendre-2", "gauss-legendre-3")
HENON_HEILES_TEXT = "Hénon–Heiles on R^4 (canonical), 64 states, h in [1e-3, 0.5]"
CONSTANT_PI_TEXT = ("Π = hat((1,2,3)) constant and degenerate, H = ½(x1²+2x2²+3x3²) + x1x2x3; 64 states, "
                    "h in [1e-3, 0.5]")


def iff_verdict(rows, key):
    """rows: name -> {(2.7) holds, measured property holds}; 'iff' confirmed when they agree."""
    agree = all(r["condition_2_7_holds"] == r[key] for r in rows.values())
    return "confirmed" if agree else "refuted"


def claim_eq25(ctx):
    statement = "(2.5): the modified Euler integrator is (x_{n+1} − x_n)/h = f(x_n) + f(x_{n+1})"
    body = paper_body()
    printed = runge_kutta(body, tableaus["modified-euler-as-printed"])
    trap = runge_kutta(body, tableaus["trapezoid"])
    xs, hs = random_unit_states(jax.random.PRNGKey(81), 64), log_steps(82, 64, hi=0.3)
    same = max_defect(lambda x, h: jnp.max(jnp.abs(printed(x, h) - trap(x, 2 * h))), xs, hs)
    m0 = jnp.asarray(PAPER_M0)
    counts = (100, 200, 400)
    _, to_t = global_errors(printed, m0, 1.0, counts, symmetric_solution(body, m0, 1.0))
    _, to_2t = global_errors(printed, m0, 1.0, counts, symmetric_solution(body, m0, 2.0))
    ev = {"max_|printed(x, h) − trapezoid(x, 2h)|": same,
          "error_vs_x(T=1)_for_n=100,200,400": [float(e) for e in to_t],
          "error_vs_x(2T)_for_n=100,200,400": [float(e) for e in to_2t],
          "order_of_consistency_(tableau)": 0}
    inconsistent = min(float(e) for e in to_t) > 1e-3
    if not inconsistent:
        verdict = "confirmed"
    else:
        verdict = "corrected" if holds(same) else "refuted"
    notes = ("As printed (Σb = 2) the method is inconsistent: it is exactly the trapezoidal rule with step "
             "2h and converges to x(2T), not x(T). With the missing ½ it is the trapezoidal rule "
             "(implemented as 'trapezoid').")
    return record("eq2.5", statement, verdict, ev, notes), None


def claim_ex21_i(ctx):
    statement = ("Ex. 2.1(i): the Ruth map (2.6) does not conserve H = (q²+p²)/2; "
                 "H(x_{n+1}) = (1+h²)H(x_n) + h²(h²/2−1)x²_n + h³x¹_n x²_n")
    step = Ruth()
    xs, hs = samples(2, 11), log_steps(12)
    energy = lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2)

    def terms(x, h):
        new = energy(step(x, h))
        printed = (1 + h**2) * energy(x) + h**2 * (h**2 / 2 - 1) * x[1] + h**3 * x[0] * x[1]
        corrected = (1 + h**2) * energy(x) + h**2 * (h**2 / 2 - 1) * x[1] ** 2 + h**3 * x[0] * x[1]
        scale = 1 + energy(x)
        return (jnp.abs(new - printed) / scale, jnp.abs(new - corrected) / scale,
                jnp.abs(new - energy(x)) / energy(x))

    printed, corrected, change = (np.asarray(v) for v in jax.jit(jax.vmap(terms))(xs, hs))
    ev = {"samples": N_SAMPLES, "h_range": list(H_RANGE),
          "max_relative_energy_change": float(change.max()),
          "max_residual_printed_formula": float(printed.max()),
          "max_residual_with_(x2)^2": float(corrected.max())}
    not_conserved = change.max() > INVARIANT_FLOOR
    if not not_conserved:
        verdict = "refuted"
    elif holds(printed.max()):
        verdict = "confirmed"
    elif holds(corrected.max()):
        verdict = "corrected"
    else:
        verdict = "refuted"
    notes = ("Expanding (2.6): H(x_{n+1}) = (1+h²)H(x_n) + h²(h²/2−1)(x²_n)² + h³x¹_n x²_n — the middle term "
             "is quadratic in x², not linear as printed.")
    return record("ex2.1-i", statement, verdict, ev, notes), None


def claim_ex21_ii(ctx):
    statement = "Ex. 2.1(ii): the Ruth map (2.6) is symplectic, dx²_{n+1}∧dx¹_{n+1} = dx²_n∧dx¹_n"
    xs, hs = samples(2, 13), log_steps(14, hi=2.0)
    step = Ruth()
    sym = max_defect(lambda x, h: symplectic_defect(step, x, h), xs, hs)
    det = max_defect(lambda x, h: jnp.abs(jnp.linalg.det(jax.jacfwd(lambda y: step(y, h))(x)) - 1), xs, hs)
    euler = runge_kutta(harmonic_oscillator(), "explicit-euler")
    control = max_defect(lambda x, h: symplectic_defect(euler, x, h), xs, jnp.full(N_SAMPLES, 0.1))
    ev = {"max_symplectic_defect": sym, "max_|det DΦ − 1|": det, "h_range": [1e-3, 2.0],
          "control_explicit_euler_defect_h0.1": control}
    verdict = "confirmed" if holds(max(sym, det)) else "refuted"
    return record("ex2.1-ii", statement, verdict, ev, "control: explicit Euler gives h² exactly"), None


def rk_tables(ctx):
    """For every tableau: max symplectic defect (Hénon–Heiles, canonical) and max Poisson defect
    (constant degenerate Π) over states and h in [1e-3, 0.5]; ONE compilation per tableau."""
    if "rk-tables" in ctx:
        return ctx["rk-tables"]
    hh = canonical_system(_henon_heiles, 4, "henon-heiles")
    cp = constant_poisson_system(_CONSTANT_PI, _cubic_energy, "constant-hat")
    xs4, xs3, hs = samples(4, 21, 64, 0.5), samples(3, 41, 64, 0.5), log_steps(22, 64, hi=0.5)
    names = _SATISFY + _VIOLATE
    coefs = [padded_coefficients(tableaus[n], 4) for n in names]
    a_all, b_all = jnp.asarray(np.stack([c[0] for c in coefs])), jnp.asarray(np.stack([c[1] for c in coefs]))

    def both(a, b):
        sym = jax.vmap(lambda x, h: symplectic_defect(runge_kutta_coefficients(hh, a, b), x, h))(xs4, hs)
        poisson_step = runge_kutta_coefficients(cp, a, b)
        poi = jax.vmap(lambda x, h: poisson_defect(poisson_step, cp.poisson_matrix, x, h))(xs3, hs)
        return jnp.max(sym), jnp.max(poi)

    sym_all, poi_all = (np.asarray(v) for v in jax.jit(jax.vmap(both))(a_all, b_all))
    rows = {}
    for name, sym, poi in zip(names, sym_all, poi_all):
        c27 = condition_2_7_defect(tableaus[name])
        rows[name] = {"condition_2_7_defect": c27, "condition_2_7_holds": c27 <= 1e-14,
                      "max_symplectic_defect": float(sym), "symplectic": holds(float(sym)),
                      "max_poisson_defect": float(poi), "poisson": holds(float(poi))}
    ctx["rk-tables"] = rows
    return rows


def method_rows(rows, names, keys):
    return {n: {k: rows[n][k] for k in keys} for n in names}


def claim_prop21(ctx):
    statement = ("Prop. 2.1: the Gauss–Legendre integrator of a canonical system (R^{2n}, Σdp∧dq, H) is "
                 "symplectic")
    rows = rk_tables(ctx)
    methods = method_rows(rows, GAUSS_LEGENDRE, ("max_symplectic_defect",))
    ev = {"system": HENON_HEILES_TEXT, "methods": methods}
    verdict = "confirmed" if all(rows[n]["symplectic"] for n in GAUSS_LEGENDRE) else "refuted"
    return record("prop2.1", statement, verdict, ev), None


def claim_prop22(ctx):
    statement = ("Prop. 2.2: an s-stage RK method is symplectic (canonical systems) iff "
                 "b_i a_ij + b_j a_ji − b_i b_j = 0 (2.7)")
    rows = rk_tables(ctx)
    keys = ("condition_2_7_defect", "condition_2_7_holds", "max_symplectic_defect", "symplectic")
    ev = {"system": HENON_HEILES_TEXT, "methods": method_rows(rows, rows, keys)}
    notes = "(2.7) holds for GL1-3 and a 2-stage DIRK (two midpoint half-steps); fails for the rest"
    return record("prop2.2", statement, iff_verdict(rows, "symplectic"), ev, notes), None


# (ids a function records, function), in the paper's order
CLAIMS = ((("eq2.5",), claim_eq25), (("ex2.1-i",), claim_ex21_i), (("ex2.1-ii",), claim_ex21_ii),
          (("prop2.1",), claim_prop21), (("prop2.2",), claim_prop22))
