"""Claims of §3 of the seed paper (Poisson integrators): Example 3.1 (i)–(iv) (one-stage
Runge–Kutta maps for Π = [[0, x2], [−x2, 0]], H linear) and Propositions 3.1–3.2 (constant Π).
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..checks._invariants import monitor_invariants
from ..checks._poisson import poisson_defect, random_unit_states
from ..classical._runge_kutta import (
    ButcherTableau,
    padded_coefficients,
    runge_kutta,
    runge_kutta_coefficients,
    tableaus,
)
from ..core._integrate import integrate
from ..systems._hamilton_poisson import example_3_1, rigid_body_system
from ..systems._rigid_body import STANDARD_CASE, RigidBody
from ..systems.so3 import hat
from ._measure import H_RANGE, log_steps, max_defect, samples, scalar
from ._records import holds, record
from ._section2 import CONSTANT_PI_TEXT, GAUSS_LEGENDRE, iff_verdict, method_rows, rk_tables


def _one_stage(a, b) -> ButcherTableau:
    """The paper's '1-step Runge–Kutta': X = x + h a f(X), x' = x + h b f(X) (any a, b)."""
    return ButcherTableau(f"one-stage(a={a:g}, b={b:g})", ((a,),), (b,), 0)


def _ex31_grid():
    """(A, B, a, b, h) with 1 + a h A != 0; the paper's h = 1/(2bA − aA) added where defined."""
    rows = []
    for big_a, big_b in ((1.0, 2.0), (-0.7, 1.3), (2.0, -0.5)):
        for a in (0.0, 0.25, 0.5, 1.0):
            for b in (0.5, 1.0, 2.0):
                hs = [0.05, 0.3, 0.9]
                if (2 * b - a) * big_a != 0:
                    hs.append(1.0 / ((2 * b - a) * big_a))
                for h in hs:
                    if abs(1 + a * h * big_a) > 1e-3 and h != 0:
                        rows.append((big_a, big_b, a, b, h))
    return rows


def _one_stage_step(system, a, b):
    """The paper's 1-stage RK map X = x + h a f(X), x' = x + h b f(X), with traced (a, b)."""
    return runge_kutta_coefficients(system, jnp.reshape(a, (1, 1)), jnp.reshape(b, (1,)))


def _ex31_measure(ctx):
    """Poisson defect and energy change of every 1-stage RK case, one compilation in all."""
    if "ex3.1" in ctx:
        return ctx["ex3.1"]
    xs = samples(2, 31, 32)
    cases = _ex31_grid() + [(0.0, 1.5, 0.5, 1.0, 0.3), (1.5, 0.0, 0.5, 1.0, 0.3), (0.0, 1.5, 1.0, 2.0, 0.9)]
    arr = jnp.asarray(np.asarray(cases))

    def measure(big_a, big_b, a, b, h):
        system = example_3_1(big_a, big_b, 0.4)
        step = _one_stage_step(system, a, b)

        def one(x):
            change = jnp.abs(system.hamiltonian(step(x, h)) - system.hamiltonian(x))
            relative_change = change / (1 + jnp.abs(system.hamiltonian(x)))
            return poisson_defect(step, system.poisson_matrix, x, h), relative_change

        d, e = jax.vmap(one)(xs)
        return jnp.max(d), jnp.max(e)

    defect, energy = jax.jit(jax.vmap(measure))(*arr.T)
    # the traced-coefficient map is the library's runge_kutta with the same tableau
    big_a, big_b, a, b, h = cases[5]
    system = example_3_1(big_a, big_b, 0.4)
    traced, library = _one_stage_step(system, a, b), runge_kutta(system, _one_stage(a, b))
    same = scalar(jnp.max(jnp.abs(traced(xs[0], h) - library(xs[0], h))))
    ctx["ex3.1"] = (cases, np.asarray(defect), np.asarray(energy), same)
    return ctx["ex3.1"]


def claim_ex31_i(ctx):
    statement = ("Ex. 3.1(i): for Π = [[0, x2], [−x2, 0]], H = Ax1 + Bx2 + C, the 1-stage RK method is "
                 "Poisson iff h = 1/(2bA − aA), 2bA − aA ≠ 0")
    cases, defect, _, same = _ex31_measure(ctx)
    on_paper_h = np.array([(2 * b - a) * big_a != 0 and abs(h - 1 / ((2 * b - a) * big_a)) < 1e-15
                           for big_a, big_b, a, b, h in cases])
    xs = samples(2, 31, 32)
    bad = lambda x, h: jnp.array([x[0], x[1] + h * x[1] ** 2])
    control = max_defect(lambda x, h: poisson_defect(bad, _ex31_pi, x, h), xs, jnp.full(32, 0.3))
    ev = {"cases": len(cases), "cases_with_paper_h": int(on_paper_h.sum()),
          "a_values": sorted({c[2] for c in cases}), "b_values": sorted({c[3] for c in cases}),
          "max_defect_at_paper_h": float(defect[on_paper_h].max()),
          "max_defect_elsewhere": float(defect[~on_paper_h].max()),
          "control_non_poisson_map_defect": control, "traced_map_vs_runge_kutta": same}
    if holds(defect[on_paper_h].max()) and not holds(defect[~on_paper_h].min()):
        verdict = "confirmed"
    else:
        verdict = "refuted"
    notes = ("f(x) = (Bx2, −Ax2) is linear, so any RK step is x ↦ R x with R upper triangular, R11 = 1: det "
             "R = R22 and (3.2) reads det(R) x2 = (Rx)2 — true for every h, a, b. The method is Poisson "
             "unconditionally; the printed condition is not necessary. The control map x2 ↦ x2 + h x2² "
             "shows the check does detect non-Poisson maps of this structure.")
    return record("ex3.1-i", statement, verdict, ev, notes), None


def _ex31_pi(x):
    return example_3_1().poisson_matrix(x)


def claim_ex31_ii(ctx):
    statement = "Ex. 3.1(ii): the 1-stage RK method conserves H = Ax1 + Bx2 + C iff A = 0 or B = 0"
    cases, _, energy, _ = _ex31_measure(ctx)
    both = np.array([big_a != 0 and big_b != 0 for big_a, big_b, *_ in cases])
    ev = {"cases_with_A≠0_and_B≠0": int(both.sum()), "cases_with_A=0_or_B=0": int((~both).sum()),
          "max_rel_energy_change_when_A≠0_and_B≠0": float(energy[both].max()),
          "max_rel_energy_change_when_A=0_or_B=0": float(energy[~both].max())}
    verdict = "confirmed" if (holds(energy[~both].max()) and not holds(energy[both].min())) else "refuted"
    notes = ("∇H·f = A·Bx2 + B·(−Ax2) = 0 identically: H is a LINEAR first integral, and every RK method "
             "(any a, b, h) preserves linear invariants exactly. Energy is conserved for all A, B.")
    return record("ex3.1-ii", statement, verdict, ev, notes), None


def claim_ex31_iii_iv(ctx):
    xs, hs = samples(2, 33, 64), log_steps(34, 64)
    coefficients = jnp.array([[1.0, 2.0], [-0.7, 1.3], [2.0, -0.5]])
    poisson, energy = {}, {}
    coefs = [padded_coefficients(tableaus[n], 3) for n in GAUSS_LEGENDRE]
    a_all, b_all = jnp.asarray(np.stack([c[0] for c in coefs])), jnp.asarray(np.stack([c[1] for c in coefs]))

    def measure(a, b, ab):
        system = example_3_1(ab[0], ab[1], 0.4)
        step = runge_kutta_coefficients(system, a, b)
        d = jax.vmap(lambda x, h: poisson_defect(step, system.poisson_matrix, x, h))(xs, hs)
        traj = integrate(step, jnp.array([0.3, 0.8]), 0.1, 100, save_every=1)
        return jnp.max(d), monitor_invariants(system, traj)["energy"].max_relative

    over_systems = jax.vmap(measure, in_axes=(None, None, 0))
    d_all, e_all = jax.jit(jax.vmap(over_systems, in_axes=(0, 0, None)))(a_all, b_all, coefficients)
    for name, d_row, e_row in zip(GAUSS_LEGENDRE, np.asarray(d_all), np.asarray(e_all)):
        columns = [f"A={ab[0]:g}, B={ab[1]:g}" for ab in np.asarray(coefficients)]
        poisson[name] = dict(zip(columns, d_row.tolist()))
        energy[name] = dict(zip(columns, e_row.tolist()))
    worst_poisson = max(v for row in poisson.values() for v in row.values())
    worst_energy = max(v for row in energy.values() for v in row.values())
    r3 = record("ex3.1-iii",
                "Ex. 3.1(iii): the Gauss–Legendre integrator is a Poisson integrator for Example 3.1",
                "confirmed" if holds(worst_poisson) else "refuted",
                {"max_poisson_defect": poisson, "h_range": list(H_RANGE)},
                "true, and for the reason found in ex3.1-i: every RK method is Poisson here")
    r4 = record("ex3.1-iv", "Ex. 3.1(iv): the Gauss–Legendre integrator conserves the energy of Example 3.1",
                "confirmed" if holds(worst_energy) else "refuted",
                {"max_relative_energy_error_100_steps_h0.1": energy},
                "H is linear and every RK method keeps linear invariants (see ex3.1-ii)")
    return [r3, r4], None


def claim_prop31(ctx):
    statement = "Prop. 3.1: for constant Π, an s-stage RK method is Poisson iff (2.7) holds"
    rows = rk_tables(ctx)
    keys = ("condition_2_7_defect", "condition_2_7_holds", "max_poisson_defect", "poisson")
    ev = {"system": CONSTANT_PI_TEXT, "methods": method_rows(rows, rows, keys)}
    return record("prop3.1", statement, iff_verdict(rows, "poisson"), ev), None


def claim_prop32(ctx):
    statement = "Prop. 3.2: for constant Π the Gauss–Legendre integrator is Poisson"
    rows = rk_tables(ctx)
    ev = {"system": CONSTANT_PI_TEXT, "methods": method_rows(rows, GAUSS_LEGENDRE, ("max_poisson_defect",))}
    body = rigid_body_system(RigidBody(jnp.asarray(STANDARD_CASE.inertia), allow_nonphysical=True))
    mid = runge_kutta(body, tableaus["implicit-midpoint"])
    ev["contrast_GL1_on_the_rigid_body_(Π(m) = hat(m))_h0.1"] = max_defect(
        lambda x, h: poisson_defect(mid, hat, x, h), random_unit_states(jax.random.PRNGKey(44), 64),
        jnp.full(64, 0.1))
    verdict = "confirmed" if all(rows[n]["poisson"] for n in GAUSS_LEGENDRE) else "refuted"
    return record("prop3.2", statement, verdict, ev,
                   "the hypothesis matters: for the Lie–Poisson Π(m) = hat(m) of an asymmetric body the "
                   "midpoint rule is not Poisson"), None


# (ids a function records, function), in the paper's order
CLAIMS = ((("ex3.1-i",), claim_ex31_i), (("ex3.1-ii",), claim_ex31_ii),
          (("ex3.1-iii", "ex3.1-iv"), claim_ex31_iii_iv), (("prop3.1",), claim_prop31),
          (("prop3.2",), claim_prop32))
