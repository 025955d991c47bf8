"""Claims of the remarks closing §4 of the seed paper: Lie–Trotter is not an energy integrator
(4.1); compared with RK4 it gives almost the same results (4.2: accuracy and invariants at
equal cost, and when RK4's drift overtakes Lie–Trotter's bounded error); the characteristic
roots of M·N·P and of the linearised map at the relative equilibria (4.4); the orbit
Π_n = Rⁿ Π_0 (4.5). Remark 4.3 only cites other work.

Cost model for Remark 4.2: one exact axis rotation (one sin/cos pair and a 3×3 rotation) and
one evaluation of the vector field m × I⁻¹m are each one unit; Lie–Trotter costs 3 units a
step, Strang 4 (5 rotations, the last merged with the next step's first), RK4 4 (four field
evaluations).
"""

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..checks._invariants import monitor_invariants
from ..classical._runge_kutta import runge_kutta, tableaus
from ..core._integrate import integrate
from ..systems._rigid_body import PAPER_M0, RigidBody, symmetric_solution
from ..systems._splitting import splitting
from ..systems.so3 import rotation_matrix
from ._measure import paper_body, scalar
from ._records import (
    INVARIANT_FLOOR,
    ROUND_OFF,
    SAME_RESULTS_FACTOR,
    answer_from_defect,
    holds,
    question_verdict,
    record,
)
from ._report import number

LONG_RUN_T, LONG_RUN_BUDGET = 1000.0, 40  # the invariant runs: horizon, cost units per unit time
DRIFT_FIT_FROM = 0.1  # a drifting error's power law is fitted on t >= this fraction of the horizon
GROWTH_MIN = 0.1  # a fitted exponent at or below this is "not growing" (a bounded error fits p ≈ 0)
TAU_TOL = 5e-11  # |half-trace| of the 2×2 tangent block above 1 + this: the pair is off the unit circle


def _methods(body):
    """name -> (step, cost units per step) for the equal-cost comparisons."""
    return {"lie-trotter": (splitting(body, "lie-trotter"), 3), "strang": (splitting(body, "strang"), 4),
            "rk4": (runge_kutta(body, tableaus["rk4"]), 4)}


def _invariant_runs(ctx):
    """Relative energy / Casimir errors of each method over T = 1000 at equal cost (~1000 samples)."""
    if "runs" in ctx:
        return ctx["runs"]
    body, m0 = paper_body(), jnp.asarray(PAPER_M0)
    e0, c0 = scalar(body.hamiltonian(m0)), scalar(body.casimir(m0))
    runs = {}
    for name, (step, cost) in _methods(body).items():
        h = cost / LONG_RUN_BUDGET
        n = round(LONG_RUN_T / h)
        traj = integrate(step, m0, h, n, save_every=max(1, n // 1000))
        inv = monitor_invariants(body, traj)
        runs[name] = {"h": h, "t": np.asarray(traj.t), "energy": np.asarray(inv["energy"].relative),
                      "casimir": np.asarray(inv["casimir"].relative),
                      "energy_drift": scalar(inv["energy"].drift) / abs(e0),
                      "casimir_drift": scalar(inv["casimir"].drift) / abs(c0)}
    ctx["runs"] = runs
    return runs


def _halves_ratio(errors) -> float:
    """max over the second half of a run / max over the first half: ~1 for a bounded error."""
    half = len(errors) // 2
    return float(errors[half:].max() / errors[:half].max())


def claim_rem41(ctx):
    lt = _invariant_runs(ctx)["lie-trotter"]
    body, m0 = paper_body(), jnp.asarray(PAPER_M0)
    cas = splitting(body, "lie-trotter", "casimir")
    traj = integrate(cas, m0, 0.075, 2000, save_every=20)
    cas_err = scalar(monitor_invariants(body, traj)["energy"].max_relative)
    energy, casimir = float(lt["energy"].max()), float(lt["casimir"].max())
    halves = _halves_ratio(lt["energy"])
    ev = {"h": lt["h"], "T": LONG_RUN_T, "max_relative_energy_error": energy,
          "relative_energy_drift_per_unit_time": lt["energy_drift"],
          "max_energy_error_second_half_/_first_half": halves, "max_relative_casimir_error": casimir,
          "casimir_split_lie_trotter_max_relative_energy_error_(T=150)": cas_err}
    verdict = "confirmed" if energy > INVARIANT_FLOOR else "refuted"
    notes = (f"Three-piece Lie–Trotter (4.1) at h = {lt['h']:g}: the energy error reaches "
             f"{number(energy, 2)} and stays bounded (maxima of the two halves of the run in ratio "
             f"{halves:.2f}; curve in the figure under rem4.2), the Casimir stays at round-off "
             f"({number(casimir, 1)}). With the Casimir-shifted split H − C/I1 = ½(1/I3 − 1/I1) m3² the "
             "symmetric body has ONE piece and Lie–Trotter is the exact flow, hence energy-preserving "
             f"(measured {number(cas_err, 1)}).")
    statement = "Rem. 4.1: the Lie–Trotter integrator is not an energy integrator"
    return record("rem4.1", statement, verdict, ev, notes), None


def _budget_runs(step, body, m0, hs, ns):
    """Final states and max relative energy / Casimir errors for n_i steps of size h_i, all in ONE
    compiled scan (steps beyond n_i are masked)."""
    n_max = int(max(ns))

    def run(h, n):
        e0, c0 = body.hamiltonian(m0), body.casimir(m0)

        def advance(carry, i):
            x, e_max, c_max = carry
            y = jnp.where(i < n, step(x, h), x)
            return (y, jnp.maximum(e_max, jnp.abs(body.hamiltonian(y) / e0 - 1)),
                    jnp.maximum(c_max, jnp.abs(body.casimir(y) / c0 - 1))), None

        zero = jnp.zeros((), m0.dtype)
        return jax.lax.scan(advance, (m0, zero, zero), jnp.arange(n_max))[0]

    return jax.jit(jax.vmap(run))(jnp.asarray(hs, m0.dtype), jnp.asarray(ns))


def power_law(t, err, fit_from=DRIFT_FIT_FROM):
    """(c, p) of err ≈ c·t^p, least squares in log-log over t >= fit_from·t[-1] (positive errors only)."""
    t, err = np.asarray(t, float), np.asarray(err, float)
    use = (t >= fit_from * t[-1]) & (t > 0) & (err > 0) & np.isfinite(err)
    if use.sum() < 2:
        return 0.0, 0.0
    p, log_c = np.polyfit(np.log(t[use]), np.log(err[use]), 1)
    return float(math.exp(log_c)), float(p)


def crossover_time(t, drifting, amplitude, fit_from=DRIFT_FIT_FROM):
    """When an error sampled as ``drifting`` at times ``t`` first exceeds a bounded error of
    ``amplitude``: (time or None, how, fitted exponent p).

    ``how`` is "measured" when it already does within the samples (the first such time),
    "extrapolated" when the power law c·t^p fitted on t >= fit_from·t[-1] grows (p > GROWTH_MIN)
    and reaches ``amplitude`` at t* = (amplitude/c)^(1/p), "never" when it does not grow.
    """
    t, drifting = np.asarray(t, float), np.asarray(drifting, float)
    c, p = power_law(t, drifting, fit_from)
    above = drifting > amplitude
    if above.any():
        return float(t[np.argmax(above)]), "measured", p
    if p <= GROWTH_MIN or c <= 0:
        return None, "never", p
    return float((amplitude / c) ** (1 / p)), "extrapolated", p


def _crossover_sentence(invariant, lt_amplitude, halves, rk_final, crossing, t_end):
    """One sentence comparing RK4's drifting error with Lie–Trotter's, from the measurements."""
    when, how, p = crossing
    if holds(lt_amplitude):
        lt = f"Lie–Trotter's round-off level {number(lt_amplitude, 2)}"
    else:
        lt = (f"Lie–Trotter's bounded {number(lt_amplitude, 2)} (maxima of the two halves of the run in "
              f"ratio {halves:.2f})")
    grows = f"{invariant}: RK4's error grows like t^{p:.2f} to {number(rk_final, 2)} at T = {t_end:g}"
    if how == "measured":
        return f"{grows} and exceeds {lt} from t = {number(when, 3)} on (measured)."
    if how == "never":
        return (f"{invariant}: RK4's error does not grow (fitted t^{p:.2f}) and stays below {lt}: "
                "no crossover.")
    return (f"{grows}, {number(lt_amplitude / rk_final, 2)} times below {lt}. If that power law (fitted on t "
            f"≥ {DRIFT_FIT_FROM * t_end:g}) continues and Lie–Trotter's error stays bounded, RK4's error "
            f"overtakes it at t ≈ {number(when, 2)} (extrapolated).")


def _equal_cost_table(body, m0, t_end, budgets):
    """{"method, budget units": h, global error at t_end, max relative energy / Casimir errors}."""
    table = {}
    for name, (step, cost) in _methods(body).items():
        hs = np.array([cost / b for b in budgets])
        ns = np.array([round(t_end / h) for h in hs])
        ends, e_max, c_max = (np.asarray(v) for v in _budget_runs(step, body, m0, hs, ns))
        for b, h, n, end, e, c in zip(budgets, hs, ns, ends, e_max, c_max):
            err = scalar(jnp.max(jnp.abs(end - symmetric_solution(body, m0, n * h))))
            table[f"{name}, {b} units"] = {"h": float(h), "global error": err,
                                           "max rel. energy error": float(e),
                                           "max rel. Casimir error": float(c)}
    return table


def _wall_clock(body, m0, steps=100_000) -> dict:
    """A second, machine-dependent cost model: microseconds per step (best of two timed runs)."""
    wall = {}
    for name, (step, _) in _methods(body).items():
        integrate(step, m0, 0.01, steps).final.block_until_ready()  # compile
        best = math.inf
        for h in (0.02, 0.03):
            start = time.perf_counter()
            integrate(step, m0, h, steps).final.block_until_ready()
            best = min(best, time.perf_counter() - start)
        wall[name] = best / steps * 1e6
    return wall


def _drift_against_bounded(runs):
    """For energy and Casimir: Lie–Trotter's maximum, RK4's growth and when RK4's error exceeds it."""
    lt, rk = runs["lie-trotter"], runs["rk4"]
    table, sentences, fits = {}, [], {}
    for invariant in ("energy", "casimir"):
        amplitude, halves = float(lt[invariant].max()), _halves_ratio(lt[invariant])
        crossing = crossover_time(rk["t"], rk[invariant], amplitude)
        when, how, p = crossing
        fits[invariant] = (*power_law(rk["t"], rk[invariant]), amplitude, when)
        table[invariant] = {
            "Lie–Trotter max over the run": amplitude, "Lie–Trotter max, second half / first half": halves,
            f"RK4 at T = {LONG_RUN_T:g}": float(rk[invariant][-1]),
            f"RK4 growth exponent p (fit on t ≥ {DRIFT_FIT_FROM * LONG_RUN_T:g})": p,
            "RK4 exceeds Lie–Trotter from t": when if when is not None else "never", "how": how}
        rk_final = float(rk[invariant][-1])
        sentences.append(_crossover_sentence(invariant.capitalize(), amplitude, halves, rk_final, crossing,
                                             LONG_RUN_T))
    return table, sentences, fits


def claim_rem42(ctx):
    statement = ("Rem. 4.2: compared with RK4 (4 stages) Lie–Trotter gives almost the same results and is "
                 "much easier to implement")
    body, m0 = paper_body(), jnp.asarray(PAPER_M0)
    t_end, budgets = 100.0, (40, 120, 400)  # budgets: cost units per unit time
    table = _equal_cost_table(body, m0, t_end, budgets)
    error = lambda name, b: table[f"{name}, {b} units"]["global error"]
    ratios = {f"{b} units": error("lie-trotter", b) / error("rk4", b) for b in budgets}
    wall = _wall_clock(body, m0)
    runs = _invariant_runs(ctx)
    long_run = {name: {"h": run["h"], "max rel. energy error": float(run["energy"].max()),
                       "energy drift (rel./unit time)": run["energy_drift"],
                       "max rel. Casimir error": float(run["casimir"].max()),
                       "Casimir drift (rel./unit time)": run["casimir_drift"]} for name, run in runs.items()}
    crossings, sentences, fits = _drift_against_bounded(runs)
    ev = {"cost_model": "1 unit = one exact rotation = one vector-field evaluation; LT 3/step, Strang 4/step "
                        "(merged), RK4 4/step",
          "T": t_end, f"equal_cost_runs_(global_error_at_T={t_end:g})": table,
          "global_error_ratio_LT/RK4": ratios,
          "wall_clock_microseconds_per_step_(this_machine)": wall,
          f"invariants_T={LONG_RUN_T:g}_at_{LONG_RUN_BUDGET}_units": long_run,
          "RK4_drift_against_Lie–Trotter": crossings}
    within = [1 / SAME_RESULTS_FACTOR <= r <= SAME_RESULTS_FACTOR for r in ratios.values()]
    verdict = "confirmed" if all(within) else ("refuted" if not any(within) else "corrected")
    low, high = min(ratios.values()), max(ratios.values())
    lt_h, rk_h = runs["lie-trotter"]["h"], runs["rk4"]["h"]
    accuracy = (f"Accuracy at equal cost: Lie–Trotter's global error at T = {t_end:g} is {number(low, 2)}–"
                f"{number(high, 2)} times RK4's ({', '.join(str(b) for b in budgets)} units per unit time; "
                f"'almost the same' would be within {SAME_RESULTS_FACTOR:g}x).")
    invariants = (f"Invariants at equal cost ({LONG_RUN_BUDGET} units per unit time, T = {LONG_RUN_T:g}; "
                  f"Lie–Trotter h = {lt_h:g}, RK4 h = {rk_h:g}):")
    cost = ("'Easier to implement' is not measurable. Second cost model, wall-clock per step on this "
            f"machine: Lie–Trotter {number(wall['lie-trotter'], 2)} µs, "
            f"Strang {number(wall['strang'], 2)} µs, RK4 {number(wall['rk4'], 2)} µs.")
    notes = " ".join([accuracy, invariants, *sentences, cost])
    figure = {"runs": runs, "fits": fits, "t_end": LONG_RUN_T}
    return record("rem4.2", statement, verdict, ev, notes), {"rem4.2": figure}


# --------------------------------------------------------------------------- Remark 4.4
_OTHER_AXES = np.array([[1, 2], [0, 2], [0, 1]])


def tangent_block(step, axis, h):
    """DΦ at the relative equilibrium m = e_axis (a fixed point of every axis-split step),
    restricted to the sphere's tangent plane there: a 2×2 block of determinant 1."""
    e = jnp.eye(3)[axis]
    jac = jax.jacfwd(lambda m: step(m, h))(e)
    others = jnp.eye(3)[jnp.asarray(_OTHER_AXES)[axis]]
    return others @ jac @ others.T


def first_departure(half_trace, grid, iterations=60, tol=TAU_TOL):
    """Where an area-preserving 2×2 family leaves the unit circle: its eigenvalues are off the
    circle iff |half_trace(h)| > 1 (+ tol). Returns (h*, status): status 1 when the pair is on the
    circle at grid[0] and first leaves at h* (bisection between the bracketing grid points,
    h* the first point found off), 2 when it is already off at grid[0] (h* = grid[0]), 0 when it
    never leaves on the grid (h* = nan). Pure jnp: jit and vmap it."""
    off = lambda h: jnp.abs(half_trace(h)) > 1 + tol
    offs = jax.vmap(off)(grid)
    i = jnp.argmax(offs)

    def bisect(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        return jnp.where(off(mid), lo, mid), jnp.where(off(mid), mid, hi)

    lo, hi = grid[jnp.maximum(i - 1, 0)], grid[i]
    h_star = jax.lax.fori_loop(0, iterations, bisect, (lo, hi))[1]
    status = jnp.where(~jnp.any(offs), 0, jnp.where(offs[0], 2, 1))
    return jnp.where(status == 1, h_star, jnp.where(status == 2, grid[0], jnp.nan)), status


_MNP_QUESTION = "M·N·P: do roots leave the unit circle?"
_DPHI_QUESTION = ("DΦ at a relative equilibrium: does a pair leave the circle onto the real line with "
                  "product 1?")


def _departure_scenario(rows) -> str | None:
    """Remark 4.4 for DΦ: "yes" when, at some equilibrium the exact flow keeps elliptic, the pair
    leaves the circle onto the real line with product 1 (to round-off); "no" when no such pair
    leaves; None when one leaves otherwise (area preservation forbids it: inconsistent measurement)."""
    left = [r for r in rows.values() if r["exact flow"] == "elliptic" and r["status"] == 1]
    if not left:
        return "no"
    real_pairs = all(holds(r["max |Im λ| just past"]) and holds(r["|λ1·λ2 − 1| just past"]) for r in left)
    return "yes" if real_pairs else None


def _exact_type(inv, axis):
    j, k = (i for i in range(3) if i != axis)
    p = (inv[axis] - inv[j]) * (inv[axis] - inv[k])
    return "hyperbolic" if p < -1e-15 else ("elliptic" if p > 1e-15 else "parabolic")


def _mnp_roots(n=2000):
    """Distance of the roots of M·N·P from the unit circle over random angle triples."""
    angles = jax.random.uniform(jax.random.PRNGKey(71), (n, 3), minval=-math.pi, maxval=math.pi)
    mnp = lambda a: rotation_matrix(0, a[0]) @ rotation_matrix(1, a[1]) @ rotation_matrix(2, a[2])
    r = jax.vmap(mnp)(angles)
    return {"random_angle_triples": n,
            "max_||λ| − 1|_of_M·N·P": scalar(jnp.max(jnp.abs(jnp.abs(jnp.linalg.eigvals(r)) - 1))),
            "max_|RᵀR − I|": scalar(jnp.max(jnp.abs(jnp.einsum("nji,njk->nik", r, r) - jnp.eye(3)))),
            "max_|det R − 1|": scalar(jnp.max(jnp.abs(jnp.linalg.det(r) - 1)))}


_BODIES = (0.6, 1.5, 2.0, 3.0)  # I = (2, s, 1): each equilibrium elliptic, hyperbolic and parabolic somewhere
_H_GRID = (0.01, 20.0, 240)  # log-spaced step sizes scanned for departures


def _equilibria():
    """DΦ of Lie–Trotter at the relative equilibria e1, e2, e3 (|m| = 1) of the bodies I = (2, s, 1):
    (rows of the table, curves of the figure); ONE compilation for every (body, axis)."""
    cases = [(s, axis) for axis in range(3) for s in _BODIES]
    h_grid = jnp.exp(jnp.linspace(math.log(_H_GRID[0]), math.log(_H_GRID[1]), _H_GRID[2]))

    def per_case(s, axis):
        step = splitting(RigidBody(jnp.stack([2.0, s, 1.0])), "lie-trotter")
        half_trace = lambda h: 0.5 * jnp.trace(tangent_block(step, axis, h))
        h_star, status = first_departure(half_trace, h_grid)
        just_past = jnp.where(jnp.isfinite(h_star), h_star * (1 + 1e-3), h_grid[0])
        lam = jnp.linalg.eigvals(tangent_block(step, axis, just_past))
        e = jnp.eye(3)[axis]
        fixed = jnp.max(jax.vmap(lambda h: jnp.max(jnp.abs(step(e, h) - e)))(h_grid))
        return jax.vmap(half_trace)(h_grid), h_star, status, half_trace(h_star), lam, fixed

    s_all, axis_all = (jnp.asarray(v) for v in zip(*cases))
    measured = jax.jit(jax.vmap(per_case))(s_all, axis_all)
    tau, h_star, status, tau_star, lam, fixed = (np.asarray(v) for v in measured)
    rows, curves = {}, {}
    for i, (s, axis) in enumerate(cases):
        label, leaves = f"I=(2,{s:g},1), m=e{axis + 1}", int(status[i]) == 1
        if leaves:
            where = float(h_star[i])
        else:
            where = (f"off already at h = {_H_GRID[0]:g}" if status[i] == 2 else
                     f"stays on (h ≤ {_H_GRID[1]:g})")
        rows[label] = {"exact flow": _exact_type(1 / np.array([2.0, s, 1.0]), axis), "status": int(status[i]),
                       f"LT at h={_H_GRID[0]:g}": "off the circle" if status[i] == 2 else "on the circle",
                       "LT leaves the circle at h": where,
                       "through λ =": ("+1" if tau_star[i] > 0 else "−1") if leaves else None,
                       "λ1, λ2 just past": np.sort(lam[i].real).tolist() if leaves else None,
                       "max |Im λ| just past": float(np.max(np.abs(lam[i].imag))) if leaves else None,
                       "|λ1·λ2 − 1| just past": float(abs(np.prod(lam[i]) - 1)) if leaves else None,
                       "fixed-point residual": float(fixed[i])}
        curves[label] = {"h": np.asarray(h_grid), "half_trace": tau[i], "h_star": where if leaves else None,
                         "axis": axis, "s": s}
    return rows, curves


def _rem44_notes(answers, mnp_off, rows):
    thresholds = {k: r["LT leaves the circle at h"] for k, r in rows.items()
                  if r["status"] == 1 and r["exact flow"] == "elliptic"}
    spurious = [k for k, r in rows.items() if r["exact flow"] == "parabolic" and r["status"] == 2]
    notes = (f"Answer for M·N·P: {answers[_MNP_QUESTION] or 'undecided'}. M·N·P is a product of rotations, "
             "an element of SO(3): its roots are 1, e^{±iα} (measured max ||λ| − 1| = "
             f"{number(mnp_off, 1)} over 2000 random angle triples), so they never leave the circle. Answer "
             "for the linearisation "
             "DΦ of the Lie–Trotter map at a relative equilibrium: "
             f"{answers[_DPHI_QUESTION] or 'undecided'}. The tangent 2×2 block has determinant 1, so its "
             "roots are λ, 1/λ: on the circle while |tr/2| ≤ 1, a real pair with product 1 beyond. ")
    if thresholds:
        first = min(thresholds, key=thresholds.get)
        notes += (f"Of the {len(thresholds)} equilibria where the exact flow is elliptic and Lie–Trotter's "
                  f"pair leaves the circle, the first threshold is h = {number(thresholds[first], 3)} "
                  f"({first}); the table gives each threshold and whether the pair leaves through λ = −1 or "
                  "+1. ")
    notes += ("The pair leaves by colliding at ±1 and splitting along the real axis; this is not a Hopf "
              "bifurcation (there a complex pair crosses the circle away from the real axis, which an "
              "area-preserving 2×2 map cannot do). ")
    if spurious:
        notes += ("Where the exact flow is parabolic (a shear: the symmetric body's equator, "
                  f"{', '.join(spurious)}) Lie–Trotter's pair is already real, off the circle, at h = "
                  f"{_H_GRID[0]:g}: a spurious instability.")
    return notes


def claim_rem44(ctx):
    statement = ("Rem. 4.4 (open problem): are there characteristic roots of M·N·P that leave the unit "
                 "circle onto the real line with product 1 ('follow a Hopf bifurcation'), a transition in "
                 "the Lie–Trotter integration of (4.2)?")
    ev = _mnp_roots()
    mnp_off = ev["max_||λ| − 1|_of_M·N·P"]
    rows, curves = _equilibria()
    answers = {_MNP_QUESTION: answer_from_defect(mnp_off), _DPHI_QUESTION: _departure_scenario(rows)}
    notes = _rem44_notes(answers, mnp_off, rows)
    for r in rows.values():
        del r["status"]
    ev["answers"] = {k: v if v is not None else "undecided" for k, v in answers.items()}
    ev["relative_equilibria_(Lie–Trotter_DΦ)"] = rows
    return record("rem4.4", statement, question_verdict(answers), ev, notes), {"rem4.4": curves}


# --------------------------------------------------------------------------- Remark 4.5
def claim_rem45(ctx):
    statement = ("Rem. 4.5 (open problem): for R = M·N·P and Π_n = R^n Π_0, Π_0 = (1,0,0), are there n for "
                 "which the 'Markov chain related to the matrix' reaches a maximal number of states?")
    body, m0, h = paper_body(), jnp.asarray(PAPER_M0), 0.1
    theta = m0 / body.inertia * h
    r = rotation_matrix(0, theta[0]) @ rotation_matrix(1, theta[1]) @ rotation_matrix(2, theta[2])
    n = 20000
    p0 = jnp.array([1.0, 0.0, 0.0])
    orbit = jax.lax.scan(lambda p, _: (r @ p, r @ p), p0, length=n)[1]
    w, v = np.linalg.eig(np.asarray(r))
    axis = np.real(v[:, np.argmin(np.abs(w - 1))])
    axis = axis / np.linalg.norm(axis)
    alpha = math.acos(max(-1.0, min(1.0, (float(jnp.trace(r)) - 1) / 2)))
    # angles of the orbit around the axis: coverage of the circle
    e1 = np.asarray(p0) - np.dot(p0, axis) * axis
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    pts = np.asarray(orbit)
    phi = np.mod(np.arctan2(pts @ e2, pts @ e1), 2 * np.pi)

    def max_gap(k):  # the largest arc of the circle not visited by Π_1 .. Π_k
        a = np.sort(phi[:k])
        return float(np.diff(np.concatenate([a, [a[0] + 2 * np.pi]])).max())

    counts = np.unique(np.geomspace(2, n, 40).astype(int))
    gaps = np.array([max_gap(k) for k in counts])
    column_sums = np.asarray(jnp.sum(r, axis=0))
    closest = float(np.min(np.linalg.norm(pts - np.asarray(p0), axis=1)))
    ev = {"angles_θ=m0·h/I": [scalar(t) for t in theta], "iterations": n,
          "max_||Π_n| − 1|": scalar(jnp.max(jnp.abs(jnp.linalg.norm(orbit, axis=1) - 1))),
          "rotation_axis": axis.tolist(), "rotation_angle_α": alpha, "α/π": alpha / math.pi,
          "max_|Π_n·axis − Π_0·axis|": float(np.max(np.abs(pts @ axis - float(np.dot(p0, axis))))),
          "closest_return_min_|Π_n − Π_0|": closest,
          f"largest_unvisited_arc_after_{n}_iterates": gaps[-1], f"2π/{n}": 2 * math.pi / n,
          "min_entry_of_R": scalar(jnp.min(r)), "column_sums_of_R": column_sums.tolist()}
    stochastic = ev["min_entry_of_R"] >= 0 and bool(np.allclose(column_sums, 1, atol=ROUND_OFF))
    # the question is about the chain: it has an answer only if R is stochastic (the chain exists)
    first_full = None
    if stochastic:
        support = np.sum(np.abs(pts) > ROUND_OFF, axis=1)
        first_full = int(np.argmax(support == 3)) + 1 if np.any(support == 3) else None
    answers = {"is R stochastic (is 'the Markov chain related to R' defined)?": "yes" if stochastic else "no",
               "first n at which the chain occupies all 3 states": first_full}  # None: undecided
    ev["answers"] = {k: v if v is not None else "undefined" for k, v in answers.items()}
    verdict = question_verdict(answers)
    notes = (f"R is orthogonal (a rotation by α = {number(alpha, 3)} about its axis), so Π_n stays on the "
             "unit sphere and on the circle cut by the plane Π·axis = const. The orbit does not come back "
             f"to Π_0 (closest return {number(closest, 2)} over n ≤ {n}) and fills that circle: the largest "
             f"unvisited arc after n iterates is {number(gaps[-1], 2)} at n = {n} (2π/n = "
             f"{number(2 * math.pi / n, 2)}). ")
    if stochastic:
        notes += "R is stochastic; the answers give the first n at which Π_n charges all three states."
    else:
        notes += ("R has negative entries and columns that do not sum to 1: it is not a stochastic matrix, "
                  "so 'the Markov chain related to the matrix' is undefined and the question cannot be "
                  "decided.")
    figure = {"orbit": pts[:4000], "axis": axis, "alpha": alpha, "counts": counts, "gaps": gaps}
    return record("rem4.5", statement, verdict, ev, notes), {"rem4.5": figure}


# (ids a function records, function), in the paper's order
CLAIMS = ((("rem4.1",), claim_rem41), (("rem4.2",), claim_rem42), (("rem4.4",), claim_rem44),
          (("rem4.5",), claim_rem45))
