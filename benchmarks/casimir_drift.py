"""How far do the Casimirs (and the attitude's Q m, QᵀQ, |q|) move over 10⁵ steps, per system,
parameter set, scheme and step size, and how does the error grow with the number of steps?

The systems and parameter sets are those of ``tests/test_systems_long_runs.py`` (two per
system: attitude with Q and with q, heavy top, Lagrange top, gravity gradient), each at
h ρ = 0.02, 0.05 and 0.2 (ρ = ``system.max_rate(x0)``, the fastest piece's rate) with Strang,
Suzuki 5, Kahan–Li 6 and Kahan–Li 8 (one compilation per system: ``roll``). Every 100th state
is saved; the table gives the largest relative error of any conserved quantity after 10³, 10⁴
and 10⁵ steps and the log-log slope of that running maximum from 10³ to 10⁵ steps (0.5: a
random walk of round-off; 1: a drift).

``python benchmarks/casimir_drift.py`` (``--quick``: 10⁴ steps, one step size).
"""

import argparse
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
jax.config.update("jax_enable_x64", True)

from _common import finish, header, log, machine_info
from test_systems_long_runs import PATHS

import jaxsplit

SCHEMES = ("strang", "suzuki-5", "kahan-li-6", "kahan-li-8")
ANGLES = (0.02, 0.05, 0.2)  # h ρ
SAVE = 100
CHECKPOINTS = (1_000, 10_000, 100_000)

monitor = eqx.filter_jit(jaxsplit.monitor_invariants)


def conserved_errors(system, trajectory, x0) -> tuple[np.ndarray, np.ndarray]:
    """(saved states,) x 2: the largest relative error of any conserved quantity (all but the
    energy) as ``monitor_invariants`` reports it (over |I(x_0)|), and the same with ⟨m, Γ⟩'s
    error over |m_0||Γ_0| instead (a small ⟨m, Γ⟩ inflates its relative error)."""
    errors = {name: e for name, e in monitor(system, trajectory).items() if name != "energy"}
    relative = np.max(np.stack([np.asarray(e.relative) for e in errors.values()]), axis=0)
    scale = {"<m,Gamma>": float(np.linalg.norm(x0[0]) * np.linalg.norm(x0[1]))}
    scaled = np.max(np.stack([np.asarray(e.absolute) / scale[name] if name in scale else np.asarray(e.relative)
                              for name, e in errors.items()]), axis=0)
    return relative, scaled


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    n_steps = 10_000 if args.quick else 100_000
    angles = ANGLES[1:2] if args.quick else ANGLES
    checkpoints = [c for c in CHECKPOINTS if c <= n_steps]
    start = time.perf_counter()
    out = machine_info("python benchmarks/casimir_drift.py" + (" --quick" if args.quick else ""))
    rows = []
    for label, family, split, _, cases in PATHS:
        length = max(len(jaxsplit.splitting(family(cases[0][0]), s, split).word) for s in SCHEMES)
        for k, (params, x0) in enumerate(cases):
            system = family(params)
            rate = float(system.max_rate(x0))
            for name in SCHEMES:
                step = jaxsplit.roll(jaxsplit.splitting(system, name, split), length)
                for angle in angles:
                    h = angle / rate
                    trajectory = jaxsplit.integrate(step, x0, h, n_steps, save_every=SAVE)
                    errors, scaled = conserved_errors(system, trajectory, x0)
                    running = np.maximum.accumulate(errors)
                    at = [float(running[c // SAVE]) for c in checkpoints]
                    slope = (float(np.polyfit(np.log(checkpoints), np.log(np.maximum(at, 1e-300)), 1)[0])
                             if len(checkpoints) > 1 and min(at) > 0 else float("nan"))
                    rows.append({"system": label, "parameter_set": k + 1, "scheme": name, "h_rho": angle,
                                 "h": h, "max_relative": dict(zip(map(str, checkpoints), at)),
                                 "max_scaled": float(np.max(scaled)), "slope": slope})
                    log(f"{label} #{k + 1} {name} hρ={angle}: {at} slope {slope:.2f}")
    out["rows"] = rows
    largest = max(rows, key=lambda r: r["max_relative"][str(checkpoints[-1])])
    lines = header(out, f"Casimir drift over {n_steps} steps (`python benchmarks/casimir_drift.py"
                        f"{' --quick' if args.quick else ''}`)")
    lines += [("Largest relative error of any conserved quantity but the energy (Casimirs; Q m and QᵀQ, or |q|, "
               "for the attitude) over the run so far, every 100th state; slope: log-log slope of that running "
               "maximum from 10³ steps on; last column: the whole run with ⟨m, Γ⟩'s error over |m₀||Γ₀| "
               "instead of |⟨m₀, Γ₀⟩| (on set 2 of the tops |⟨m₀, Γ₀⟩| is 0.04–0.07 |m₀||Γ₀|)."), "",
              "| system | set | scheme | h ρ | h | " + " | ".join(f"after {c:.0e} steps" for c in checkpoints)
              + " | slope | ⟨m, Γ⟩ over \\|m₀\\|\\|Γ₀\\| |", "|---" * (7 + len(checkpoints)) + "|"]
    for r in rows:
        lines.append(f"| {r['system']} | {r['parameter_set']} | {r['scheme']} | {r['h_rho']} | {r['h']:.3g} | "
                     + " | ".join(f"{r['max_relative'][str(c)]:.2g}" for c in checkpoints)
                     + f" | {r['slope']:.2f} | {r['max_scaled']:.2g} |")
    final = np.array([r["max_relative"][str(checkpoints[-1])] for r in rows])
    slopes = np.array([r["slope"] for r in rows])
    scaled = max(rows, key=lambda r: r["max_scaled"])
    lines += ["", "### Reading", "",
              (f"Over {len(rows)} runs the largest error after {checkpoints[-1]:.0e} steps is "
              f"{largest['max_relative'][str(checkpoints[-1])]:.2g} ({largest['system']}, set "
              f"{largest['parameter_set']}, {largest['scheme']}, h ρ = {largest['h_rho']}); median {np.median(final):.2g}. "
              f"Slopes of the running maximum: median {np.nanmedian(slopes):.2f}, range "
              f"{np.nanmin(slopes):.2f} to {np.nanmax(slopes):.2f}. With ⟨m, Γ⟩ over |m₀||Γ₀| the largest is "
              f"{scaled['max_scaled']:.2g} ({scaled['system']}, set {scaled['parameter_set']}, {scaled['scheme']}, "
              f"h ρ = {scaled['h_rho']}).")]
    out["largest"] = largest
    finish("casimir_drift", out, lines, start, args.quick)


if __name__ == "__main__":
    main()
