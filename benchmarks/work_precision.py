"""How fast does each method reach an error at T = 10³ on 256 bodies? jaxsplit against
diffrax (Tsit5, Dopri5, Dopri8; fixed steps and PID over tolerances) and scipy DOP853.

Two bodies: the standard I = (2, 1, 2/3) and the near-symmetric I = (1, 1.01, 0.5); 256
random unit states integrated together (one (256, 3) state for every method: a shared step
for the adaptive ones, whose error control then watches the worst body). Error = max over
bodies of |m(T) − reference|, the reference by Kahan–Li 10 with sub-step angles <= 0.01.
Work = wall time of one call (median of interleaved rounds), in two idioms for both JAX
libraries: the batch as one (256, 3) state (jaxsplit's ``integrate`` called directly,
dispatch included; diffrax behind ``jax.jit`` with the tolerance or step traced) and the
user's ``jax.jit(jax.vmap(...))`` over single states (each body then has its own adaptive
step in diffrax); both compiled with XLA's defaults. scipy ``solve_ivp`` on the 768
components. Time to reach 1e-6 and 1e-8 is
interpolated log-log between measured points; ``auto`` is ``jaxsplit.auto_splitting``'s
choice for that tolerance (its pilot time reported apart).

    python benchmarks/work_precision.py [--quick]

Writes ``benchmarks/results/work_precision.{md,json,png}``.
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
from _common import finish, header, interleaved, log, machine_info, result_path, scheme_label, time_to_reach
from scipy.integrate import solve_ivp

import jaxsplit

T_END = 1000.0
BODIES = {"standard I = (2, 1, 2/3)": (2.0, 1.0, 2.0 / 3.0), "near-symmetric I = (1, 1.01, 0.5)": (1.0, 1.01, 0.5)}
TARGETS = (1e-6, 1e-8)
SPLITTINGS = {  # step counts over T = 10³ (h = 10³/n), bracketing 1e-6 and 1e-8 on both bodies; the order-8
    # ladders have a point between 1250 and 2500 steps, where 1e-6 falls on the standard body (without it the
    # crossing was interpolated across 2.5 decades of error)
    "kahan-li-8": (640, 1250, 1800, 2500, 5000, 10000), "mclachlan-ss15": (640, 1250, 1800, 2500, 5000, 10000),
    "blanes-casas-murua-8": (640, 1250, 1800, 2500, 3500, 5000, 10000),
    "mclachlan-ss17": (640, 1250, 1800, 2500, 5000, 10000), "kahan-li-10": (640, 1250, 1800, 2500, 5000),
    "sofroniou-spaletta-10": (640, 1250, 1800, 2500, 5000), "kahan-li-6": (1280, 2500, 5000, 10000, 20000),
    "blanes-moan-s6-prk": (2560, 5000, 10000, 20000, 40000, 80000), "strang": (16000, 64000, 256000)}


def states():
    m = np.random.default_rng(0).standard_normal((256, 3))
    return m / np.linalg.norm(m, axis=1, keepdims=True)


def reference(body, m0):
    step = jaxsplit.splitting(body, "kahan-li-10", "casimir")
    n = int(T_END * float(jnp.max(body.max_rate(m0))) / 0.01) + 1
    return np.asarray(jaxsplit.integrate(step, m0, T_END / n, n).final)


VMAP = ", jit(vmap)"  # the method label's suffix for the user's idiom


def jaxsplit_cases(body, m0, quick):
    cases = []
    for scheme, counts in SPLITTINGS.items():
        step = jaxsplit.splitting(body, scheme, "casimir")
        for n in counts[::2] if quick else counts:
            run = lambda m, step=step, n=n: jaxsplit.integrate(step, m, T_END / n, n).final
            mapped = jax.jit(jax.vmap(run))
            cases.append((f"jaxsplit {scheme_label(scheme)}, Casimir split", f"n = {n}",
                          lambda run=run: run(m0).block_until_ready()))
            cases.append((f"jaxsplit {scheme_label(scheme)}, Casimir split{VMAP}", f"n = {n}",
                          lambda f=mapped: f(m0).block_until_ready()))
    return cases


def diffrax_cases(body, m0, quick):
    term = diffrax.ODETerm(lambda t, m, args: body.vector_field(m))
    cases = []
    solvers = {"Tsit5": (diffrax.Tsit5(), 5), "Dopri5": (diffrax.Dopri5(), 5), "Dopri8": (diffrax.Dopri8(), 8)}
    for name, (solver, order) in solvers.items():
        def adaptive(y0, tol, solver=solver):
            controller = diffrax.PIDController(rtol=tol, atol=tol)
            return diffrax.diffeqsolve(term, solver, 0.0, T_END, None, y0, stepsize_controller=controller,
                                       max_steps=10**6).ys[-1]

        for idiom, f in (("", jax.jit(adaptive)), (VMAP, jax.jit(jax.vmap(adaptive, in_axes=(0, None))))):
            for tol in ((1e-7, 1e-9, 1e-11) if quick else (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11)):
                cases.append((f"diffrax {name} (PID){idiom}", f"tol = {tol:.0e}",
                              lambda f=f, tol=tol: f(m0, jnp.asarray(tol)).block_until_ready()))
        counts = (4000, 8000, 16000, 32000) if order == 5 else (1000, 2000, 4000, 8000)
        for n in counts[::2] if quick else counts:
            def fixed(y0, dt, solver=solver, n=n):
                return diffrax.diffeqsolve(term, solver, 0.0, T_END, dt, y0, max_steps=n + 1).ys[-1]

            for idiom, f in (("", jax.jit(fixed)), (VMAP, jax.jit(jax.vmap(fixed, in_axes=(0, None))))):
                cases.append((f"diffrax {name} (fixed){idiom}", f"n = {n}",
                              lambda f=f, n=n: f(m0, jnp.asarray(T_END / n)).block_until_ready()))
    return cases


def scipy_cases(inertia, m0, quick):
    w = 1 / np.asarray(inertia)

    def rhs(t, y):
        m = y.reshape(-1, 3)
        return np.cross(m, m * w).reshape(-1)

    y0 = np.asarray(m0).reshape(-1)
    return [("scipy DOP853", f"tol = {tol:.0e}",
             lambda tol=tol: solve_ivp(rhs, (0, T_END), y0, method="DOP853", rtol=tol, atol=tol).y[:, -1].reshape(-1, 3))
            for tol in ((1e-8, 1e-11) if quick else (1e-7, 1e-8, 1e-9, 1e-10, 1e-11))]


def study(label, inertia, quick, repeats):
    body = jaxsplit.RigidBody(jnp.asarray(inertia), allow_nonphysical=True)
    m0 = jnp.asarray(states())
    ref = reference(body, m0)
    cases = jaxsplit_cases(body, m0, quick) + diffrax_cases(body, m0, quick) + scipy_cases(inertia, m0, quick)
    rows, calls = [], {}
    for method, setting, fn in cases:
        t0 = time.perf_counter()
        result = np.asarray(fn())
        log(f"{label}: {method} {setting}: first call {time.perf_counter() - t0:.2f} s")
        rows.append({"body": label, "method": method, "setting": setting,
                     "error": float(np.max(np.abs(result - ref)))})
        calls[len(rows) - 1] = fn
    times = interleaved(calls, repeats)
    for i, row in enumerate(rows):
        row["time_s"] = statistics.median(times[i])
    auto = []
    for tol in TARGETS:
        t0 = time.perf_counter()
        choice = jaxsplit.auto_splitting(body, m0, tol=tol, t_end=T_END)
        pilot = time.perf_counter() - t0
        run = lambda choice=choice: jaxsplit.integrate(choice.step, m0, choice.h, choice.n_steps).final.block_until_ready()
        result = np.asarray(run())
        run_s = statistics.median(interleaved({"run": run}, repeats)["run"])
        auto.append({"body": label, "tol": tol, "scheme": choice.scheme, "split": choice.split,
                     "n_steps": choice.n_steps, "error": float(np.max(np.abs(result - ref))), "time_s": run_s,
                     "pilot_s": pilot})
    return rows, auto


def summary(rows, auto, label):
    methods = list(dict.fromkeys(r["method"] for r in rows if r["body"] == label))
    reach = {m: {t: time_to_reach([(r["error"], r["time_s"]) for r in rows if r["body"] == label and r["method"] == m], t)
                 for t in TARGETS} for m in methods}
    best = {}
    for family in ("jaxsplit", "diffrax", "scipy"):
        for idiom in ("batch", "vmap"):
            for t in TARGETS:
                options = [(v[t], m) for m, v in reach.items() if m.startswith(family) and v[t] is not None
                           and m.endswith(VMAP) == (idiom == "vmap")]
                best[family, idiom, t] = min(options) if options else (None, None)
    return reach, best


def plot(rows, path):
    labels = list(dict.fromkeys(r["body"] for r in rows))
    fig, axes = plt.subplots(1, len(labels), figsize=(13, 5), constrained_layout=True, sharey=True)
    styles = {"jaxsplit": "-o", "diffrax": "--^", "scipy": ":s"}
    for ax, label in zip(axes, labels):
        for method in dict.fromkeys(r["method"] for r in rows if r["body"] == label
                                    and (r["method"].endswith(VMAP) or r["method"].startswith("scipy"))):
            pts = sorted((r["time_s"], max(r["error"], 1e-16)) for r in rows if r["body"] == label and r["method"] == method)
            color = "black" if method.startswith("scipy") else None  # the 11th line would repeat a colour
            ax.loglog(*zip(*pts), styles[method.split()[0]], label=method, ms=4, lw=1.2, color=color)
        for t in TARGETS:
            ax.axhline(t, color="grey", lw=0.6, ls=":")
        ax.set_title(f"{label}, 256 bodies, T = 1000, jit(vmap(...))")
        ax.set_xlabel("wall time per run [s]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("max error at T = 1000 over the 256 bodies")
    axes[-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/work_precision.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    repeats = 2 if quick else 5
    rows, auto = [], []
    for label, inertia in BODIES.items():
        r, a = study(label, inertia, quick, repeats)
        rows += r
        auto += a
    out["rows"], out["auto"] = rows, auto
    lines = header(out, "Work–precision at T = 10³, 256 bodies (`benchmarks/work_precision.py`)")
    lines += [("Time to reach a max error over the bodies (log-log interpolation between measured points; — = "
              "not bracketed) for the best configuration of each family, and the speed-up of the best jaxsplit "
              "configuration over the best diffrax one. Plot: `work_precision.png`; every point in "
              "`work_precision.json`."), "",
              "| body | error | idiom | best jaxsplit | best diffrax | scipy DOP853 | jaxsplit speed-up over diffrax |",
              "|---|---|---|---|---|---|---|"]
    out["speedups"] = {}
    for label in BODIES:
        _, best = summary(rows, auto, label)
        for t in TARGETS:
            for idiom, name in (("vmap", "`jit(vmap(...))`, both"), ("batch", "batched state, both")):
                (tj, mj), (td, md) = best["jaxsplit", idiom, t], best["diffrax", idiom, t]
                ts = best["scipy", "batch", t][0]
                ratio = td / tj if tj and td else None
                out["speedups"][f"{label}, {t:.0e}, {idiom}"] = ratio
                cell = lambda v, m: "—" if v is None else f"{v * 1e3:.3g} ms ({m.removesuffix(VMAP)})"
                lines.append(f"| {label} | {t:.0e} | {name} | {cell(tj, mj)} | {cell(td, md)} | "
                             f"{'—' if ts is None else f'{ts * 1e3:.3g} ms'} | "
                             f"{'—' if ratio is None else f'**{ratio:.2g}×**'} |")
    lines += ["", ("`auto_splitting`'s choice per tolerance (run time; the pilot that chose it, once per body and "
              "tolerance, apart):"), "", "| body | tol | choice | steps | error reached | run | pilot |",
              "|---|---|---|---|---|---|---|"]
    for a in auto:
        lines.append(f"| {a['body']} | {a['tol']:.0e} | {scheme_label(a['scheme'])}, {a['split']} split | {a['n_steps']} | "
                     f"{a['error']:.2e} | {a['time_s'] * 1e3:.3g} ms | {a['pilot_s']:.2g} s |")
    plot(rows, result_path("work_precision", "png", quick))
    finish("work_precision", out, lines, start, quick)


if __name__ == "__main__":
    main()
