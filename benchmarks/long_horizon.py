"""Over T = 10⁵, what happens to the energy and the Casimir at equal cost? Splittings against
Runge–Kutta methods given the same wall time.

Standard case (I = (2, 1, 2/3), m0 = (cos 1.1, 0, sin 1.1)), float64. Pairs: Strang (Casimir
split, h = 0.1) against diffrax Tsit5, and Kahan–Li 6 (Casimir split, h = 0.4) against
diffrax Dopri8, each Runge–Kutta method with a fixed step chosen so that its run takes the
splitting's wall time (calibrated on a short run, then measured), and with the splitting's
step. 101 saved states; relative errors of H and C = |m|²/2 against their initial values.

    python benchmarks/long_horizon.py [--quick]      # quick: T = 10⁴

Writes ``benchmarks/results/long_horizon.{md,json,png}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import finish, header, interleaved, log, machine_info, result_path, scheme_label

import jaxsplit

CASE = jaxsplit.STANDARD_CASE
BODY = jaxsplit.RigidBody(jnp.asarray(CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(CASE.m0)
PAIRS = (("strang", 0.1, "Tsit5", diffrax.Tsit5()), ("kahan-li-6", 0.4, "Dopri8", diffrax.Dopri8()))


def splitting_run(scheme, h, t_end):
    step = jaxsplit.splitting(BODY, scheme, "casimir")
    n = round(t_end / h)
    return lambda: jaxsplit.integrate(step, M0, h, n, save_every=n // 100).x.block_until_ready()


def diffrax_run(solver, n, t_end):
    term = diffrax.ODETerm(lambda t, m, args: BODY.vector_field(m))
    saveat = diffrax.SaveAt(ts=jnp.linspace(0.0, t_end, 101))
    fn = jax.jit(lambda y0: diffrax.diffeqsolve(term, solver, 0.0, t_end, t_end / n, y0, saveat=saveat,
                                                max_steps=n + 1).ys)
    return lambda: fn(M0).block_until_ready()


def errors(ms):
    ms = np.asarray(ms)
    energy = 0.5 * np.sum(ms**2 / np.asarray(CASE.inertia), axis=1)
    casimir = 0.5 * np.sum(ms**2, axis=1)
    return np.abs(energy / energy[0] - 1), np.abs(casimir / casimir[0] - 1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/long_horizon.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    t_end = 1e4 if quick else 1e5
    repeats = 3
    rows, curves = [], {}
    for scheme, h, rk_name, solver in PAIRS:
        split = splitting_run(scheme, h, t_end)
        split()
        t_split = statistics.median(interleaved({"s": split}, repeats)["s"])
        probe_n = 20_000
        probe = diffrax_run(solver, probe_n, t_end / 10)
        probe()
        per_step = statistics.median(interleaved({"p": probe}, repeats)["p"]) / probe_n
        n = max(100, round(t_split / per_step))
        runs = {"split": (split, f"jaxsplit {scheme_label(scheme)}, Casimir split, h = {h}"),
                "same time": (diffrax_run(solver, n, t_end), f"diffrax {rk_name}, h = {t_end / n:.3g} (same wall time)"),
                "same step": (diffrax_run(solver, round(t_end / h), t_end), f"diffrax {rk_name}, h = {h} (same step)")}
        for fn, _ in runs.values():
            fn()
        times = interleaved({key: fn for key, (fn, _) in runs.items()}, repeats)
        log(f"{scheme} vs {rk_name}: {n} RK steps at the same wall time (h = {t_end / n:.3g})")
        for key, (fn, label) in runs.items():
            de, dc = errors(fn())
            finite = bool(np.all(np.isfinite(de)))
            rows.append({"method": label, "time_s": statistics.median(times[key]),
                         "time_vs_splitting": statistics.median(a / b for a, b in zip(times[key], times["split"])),
                         "finite": finite, "max_energy_error": float(de.max()), "final_energy_error": float(de[-1]),
                         "energy_error_at_T/10": float(de[10]), "max_casimir_error": float(dc.max())})
            if finite:
                curves[label] = (de, dc)
    ts = np.linspace(0.0, t_end, 101)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), constrained_layout=True)
    for label, (de, dc) in curves.items():
        axes[0].loglog(ts[1:], np.maximum(de[1:], 1e-17), label=label, lw=1.2)
        axes[1].loglog(ts[1:], np.maximum(dc[1:], 1e-17), label=label, lw=1.2)
    for ax, what in zip(axes, ("energy H", "Casimir |m|²/2")):
        ax.set_xlabel("time t")
        ax.set_ylabel(f"relative error of the {what}")
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle(f"Standard rigid body over T = {t_end:g}: splittings and Runge–Kutta methods (same wall time, or same step)")
    fig.savefig(result_path("long_horizon", "png", quick), dpi=110)
    out["rows"] = rows
    lines = header(out, f"Long horizon, T = {t_end:g} (`benchmarks/long_horizon.py`)")
    lines += [("Each Runge–Kutta method runs with the wall time of the splitting it faces (fixed step calibrated, "
              "then measured) and with the splitting's step; times are medians of interleaved rounds. Relative "
              "errors at the 101 saved times. Plot: `long_horizon.png` (finite runs)."), "",
              ("| method | wall time | × splitting's time | max energy error | energy error at T/10 | at T | "
              "max Casimir error |"), "|---|---|---|---|---|---|---|"]
    for r in rows:
        errs = ([f"{r[k]:.2e}" for k in ("max_energy_error", "energy_error_at_T/10", "final_energy_error")]
                + [f"{r['max_casimir_error']:.1e}"]) if r["finite"] else ["diverged (not finite)", "—", "—", "—"]
        lines.append(f"| {r['method']} | {r['time_s']:.3g} s | {r['time_vs_splitting']:.2f} | " + " | ".join(errs) + " |")
    finish("long_horizon", out, lines, start, quick)


if __name__ == "__main__":
    main()
