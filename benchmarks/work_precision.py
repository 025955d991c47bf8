"""Work–precision on the standard rigid body: jaxsplit splittings vs scipy vs diffrax.

Error = max-norm distance of m(T = 10) from the 30-digit reference value (``STANDARD_CASE``),
work = steady-state wall time of one call (compiled; ``block_until_ready``; a
``jaxsplit.integrate`` call includes its ~30 µs Python-side dispatch, as a user sees it).
Every method runs in this one process; the timings are interleaved round-robin over all
configurations and the median of the rounds is kept (the CPU is shared: ratios, not
absolute times, are the result). The relative Casimir error |C(T) − C(0)|/C(0) is
recorded for every run (splittings: round-off; Runge–Kutta methods: drift).

Contenders:

* jaxsplit ``strang`` (axes and casimir split), ``triple-jump-4``, ``blanes-moan-s6-prk``,
  ``kahan-li-6``, ``kahan-li-8`` and ``sofroniou-spaletta-10`` (casimir split) over step
  counts: the library's generic composer (``jaxsplit.compose``) and ``jaxsplit.integrate``
  over the library's rotations computed on two components, each behind
  ``lax.optimization_barrier`` (``scalar+barrier``, the recommended form, see the README);
  kahan-li-8 also with the committed 3x3-matrix rotations, and kahan-li-6 through
  ``jaxsplit.splitting`` as the working tree has it (recorded git state);
* scipy ``solve_ivp`` DOP853 and RK45 over tolerances (rtol = atol);
* diffrax Tsit5 and Dopri8 with a PIDController over tolerances (rtol = atol, traced: one
  compilation per solver), and Tsit5 / Dopri8 with constant steps.

Also a long-time run (T = 1e4, h = 0.1): energy and Casimir errors of Strang against
DOP853 (rtol = atol = 1e-10) and diffrax Tsit5 at the same step and at matched wall time.

    python benchmarks/work_precision.py            # full, < 3 min on 2 shared cores
    python benchmarks/work_precision.py --quick    # smoke mode (T_long = 1e3, fewer points)

Writes ``benchmarks/results/work_precision{,-quick}.{md,json,png}`` and
``long_time{,-quick}.png``.
"""

import argparse
import itertools
import json
import math
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import interleaved, machine_info, step_variant
from scipy.integrate import solve_ivp

import jaxsplit

RESULTS = Path(__file__).resolve().parent / "results"
CASE = jaxsplit.STANDARD_CASE
INERTIA = np.asarray(CASE.inertia)
M0 = np.asarray(CASE.m0)
T_END = CASE.t_end
REFERENCE = np.asarray(CASE.reference)
BODY = jaxsplit.RigidBody(jnp.asarray(INERTIA))
A1, A2, A3 = (1 / v for v in INERTIA)


def log(msg: str):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def casimir(m):
    return 0.5 * float(np.dot(m, m))


def energy(m):
    m = np.asarray(m)
    return 0.5 * float(np.sum(m * m / INERTIA))


def rhs_numpy(t, m):
    """ṁ = m × I⁻¹m, written out (scipy's right-hand side)."""
    m1, m2, m3 = m
    return np.array([(A3 - A2) * m2 * m3, (A1 - A3) * m3 * m1, (A2 - A1) * m1 * m2])


def rhs_jax(t, m, args):
    return BODY.vector_field(m)


# ---------------------------------------------------------------------------------------
# contenders: each a (name, label, parameter, callable returning m(T) as a numpy array)

# The library's rotation code is being changed in the working tree while these benchmarks are
# written, so the flows are pinned by name (see _common.step_variant): ``scalar+barrier`` is the
# fast, stable form recommended in the README; ``matrix`` is the committed (HEAD) form;
# ``library`` is whatever the working tree holds (its git state is recorded in the results).
SPLITTINGS = [  # (scheme, split, variant)
    ("strang", "axes", "scalar+barrier"),
    ("strang", "casimir", "scalar+barrier"),
    ("triple-jump-4", "casimir", "scalar+barrier"),
    ("blanes-moan-s6-prk", "casimir", "scalar+barrier"),
    ("kahan-li-6", "casimir", "scalar+barrier"),
    ("kahan-li-8", "casimir", "scalar+barrier"),
    ("sofroniou-spaletta-10", "casimir", "scalar+barrier"),
    ("kahan-li-8", "casimir", "matrix"),
    ("kahan-li-6", "casimir", "library"),
]


def splitting_counts(scheme: str, quick: bool):
    full = {
        "strang": [100, 200, 400, 800, 1600, 3200, 6400, 12800],
        "triple-jump-4": [50, 100, 200, 400, 800, 1600, 3200],
        "blanes-moan-s6-prk": [25, 50, 100, 200, 400, 800, 1600],
        "kahan-li-6": [20, 40, 80, 160, 320, 640],
        "kahan-li-8": [20, 40, 80, 160, 320],
        "sofroniou-spaletta-10": [10, 20, 40, 80, 160],
    }[scheme]
    return full[::3] if quick else full


def splitting_cases(quick: bool):
    m0 = jnp.asarray(M0)
    cases = []
    for scheme, split, variant in SPLITTINGS:
        step = step_variant(BODY, scheme, split, variant, shift=1)
        label = f"jaxsplit {scheme} ({split}), " + ("working-tree library" if variant == "library"
                                                  else f"{variant} flows")
        for n in splitting_counts(scheme, quick):
            h = jnp.asarray(T_END / n)
            # the same program two ways: behind the caller's own jax.jit (as diffrax is timed
            # here), and through a plain jaxsplit.integrate call (its Python-side dispatch)
            jitted = jax.jit(lambda step, m0, h, n=n: jaxsplit.integrate(step, m0, h, n).final)

            def run(step=step, h=h, jitted=jitted):
                return np.asarray(jax.block_until_ready(jitted(step, m0, h)))

            def direct(step=step, h=h, n=n):
                return np.asarray(jax.block_until_ready(jaxsplit.integrate(step, m0, h, n).final))

            t0 = time.perf_counter()
            run()
            direct()
            log(f"{label} n={n}: first calls (compile) {time.perf_counter() - t0:.2f} s")
            cases.append({"family": "jaxsplit", "method": label, "param": f"n={n}",
                          "rotations": step.flows_per_step * n, "run": run, "direct": direct})
    return cases


def scipy_cases(quick: bool):
    tols = {"DOP853": [1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-13],
            "RK45": [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9]}
    cases = []
    for method, ts in tols.items():
        for tol in ts[::2] if quick else ts:
            def run(method=method, tol=tol):
                sol = solve_ivp(rhs_numpy, (0.0, T_END), M0, method=method, rtol=tol, atol=tol)
                return sol.y[:, -1], {"nfev": int(sol.nfev)}

            run()
            cases.append({"family": "scipy", "method": f"scipy {method}", "param": f"tol={tol:.0e}",
                          "run": run})
    return cases


def diffrax_cases(quick: bool):
    term = diffrax.ODETerm(rhs_jax)
    y0 = jnp.asarray(M0)
    cases = []
    tols = [1e-4, 1e-6, 1e-8, 1e-10, 1e-12]
    for name, solver in (("Tsit5", diffrax.Tsit5()), ("Dopri8", diffrax.Dopri8())):
        @jax.jit
        def adaptive(y0, tol, solver=solver):
            sol = diffrax.diffeqsolve(term, solver, 0.0, T_END, None, y0,
                                      stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol),
                                      max_steps=100_000)
            return sol.ys[-1], sol.stats["num_steps"]

        t0 = time.perf_counter()
        jax.block_until_ready(adaptive(y0, 1e-6))
        log(f"diffrax {name} adaptive: compile {time.perf_counter() - t0:.2f} s")
        for tol in tols[::2] if quick else tols:
            def run(adaptive=adaptive, tol=tol):
                y, steps = jax.block_until_ready(adaptive(y0, jnp.asarray(tol)))
                return np.asarray(y), {"steps": int(steps)}

            run()
            cases.append({"family": "diffrax", "method": f"diffrax {name} (PID)", "param": f"tol={tol:.0e}",
                          "run": run})

        counts = [100, 200, 400, 800, 1600, 3200] if name == "Tsit5" else [25, 50, 100, 200, 400]

        max_count = max(counts)

        @jax.jit
        def fixed(y0, dt, solver=solver, max_steps=max_count):
            sol = diffrax.diffeqsolve(term, solver, 0.0, T_END, dt, y0,
                                      stepsize_controller=diffrax.ConstantStepSize(), max_steps=max_steps)
            return sol.ys[-1]

        t0 = time.perf_counter()
        jax.block_until_ready(fixed(y0, T_END / counts[0]))
        log(f"diffrax {name} fixed: compile {time.perf_counter() - t0:.2f} s")
        for n in counts[::2] if quick else counts:
            def run(fixed=fixed, n=n):
                return np.asarray(jax.block_until_ready(fixed(y0, jnp.asarray(T_END / n))))

            run()
            cases.append({"family": "diffrax", "method": f"diffrax {name} (fixed)", "param": f"n={n}",
                          "run": run})
    return cases


# ---------------------------------------------------------------------------------------


def work_precision(quick: bool, repeats: int):
    cases = splitting_cases(quick) + scipy_cases(quick) + diffrax_cases(quick)
    log(f"timing {len(cases)} configurations, {repeats} interleaved rounds")
    fns = {i: c["run"] for i, c in enumerate(cases)}
    fns.update({(i, "direct"): c["direct"] for i, c in enumerate(cases) if "direct" in c})
    times = interleaved(fns, repeats)
    c0 = casimir(M0)
    rows = []
    for i, c in enumerate(cases):
        m = c["run"]()
        m, extra = m if isinstance(m, tuple) else (m, {})
        m = np.asarray(m)
        row = {k: v for k, v in c.items() if k not in ("run", "direct")}
        if (i, "direct") in times:
            row["time_integrate_call_s"] = statistics.median(times[(i, "direct")])
        row.update(extra)
        row.update(time_s=statistics.median(times[i]), error=float(np.max(np.abs(m - REFERENCE))),
                   casimir_error=abs(casimir(m) - c0) / c0)
        rows.append(row)
    return rows


def time_to_reach(rows, method: str, target: float):
    """Log-log interpolated wall time at which ``method`` reaches error ``target``."""
    pts = sorted((r["error"], r["time_s"]) for r in rows if r["method"] == method and r["error"] > 0)
    for (e_lo, t_lo), (e_hi, t_hi) in itertools.pairwise(pts):
        if e_lo <= target <= e_hi:
            w = (math.log(target) - math.log(e_hi)) / (math.log(e_lo) - math.log(e_hi))
            return math.exp(math.log(t_hi) + w * (math.log(t_lo) - math.log(t_hi)))
    return None


def long_time(quick: bool):
    """Energy / Casimir errors over a long run at h = 0.1 (T = 1e4; 1e3 in quick mode)."""
    t_end = 1e3 if quick else 1e4
    h = 0.1
    n = round(t_end / h)
    save_every = n // 1000
    ts = np.linspace(0.0, t_end, 1001)
    m0 = jnp.asarray(M0)
    h0, c0 = energy(M0), casimir(M0)
    out = {"t_end": t_end, "h": h}

    def errors(ms):
        ms = np.asarray(ms)
        de = np.abs(0.5 * np.sum(ms * ms / INERTIA, axis=1) - h0) / h0
        dc = np.abs(0.5 * np.sum(ms * ms, axis=1) - c0) / c0
        return de, dc

    step = step_variant(BODY, "strang", "axes", "scalar+barrier")

    def strang():
        return jax.block_until_ready(jaxsplit.integrate(step, m0, h, n, save_every=save_every)).x

    term = diffrax.ODETerm(rhs_jax)

    def tsit5_runner(n_steps):
        """Fixed-step Tsit5 with ``n_steps`` steps, every step saved (SaveAt(steps=True) is
        far cheaper than SaveAt(ts=...) here), sub-sampled to the 1001 times ``ts``."""
        every = n_steps // 1000

        @jax.jit
        def run(y0):
            sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), 0.0, t_end, t_end / n_steps, y0,
                                      saveat=diffrax.SaveAt(t0=True, steps=True),
                                      stepsize_controller=diffrax.ConstantStepSize(), max_steps=n_steps)
            return sol.ys[: n_steps + 1 : every]

        return run

    def dop853():
        return solve_ivp(rhs_numpy, (0.0, t_end), M0, method="DOP853", rtol=1e-10, atol=1e-10, t_eval=ts).y.T

    tsit5 = tsit5_runner(n)
    strang()
    jax.block_until_ready(tsit5(m0))
    # matched cost: calibrate Tsit5's time per step against Strang's, then run with that many steps
    reps = 3
    t_strang = statistics.median(_timed(strang) for _ in range(reps))
    t_tsit_same = statistics.median(_timed(lambda: jax.block_until_ready(tsit5(m0))) for _ in range(reps))
    n_matched = max(1000, 1000 * round(n * t_strang / t_tsit_same / 1000))
    h_matched = t_end / n_matched
    tsit5_matched = tsit5_runner(n_matched)
    runs = {
        "jaxsplit strang (axes), scalar+barrier flows, h = 0.1": (strang, t_strang),
        "diffrax Tsit5, fixed h = 0.1": (lambda: tsit5(m0), t_tsit_same),
    }
    ms_matched = jax.block_until_ready(tsit5_matched(m0))
    t_matched = statistics.median(_timed(lambda: jax.block_until_ready(tsit5_matched(m0)))
                                  for _ in range(reps))
    t0 = time.perf_counter()
    ms_dop = dop853()
    t_dop = time.perf_counter() - t0
    log(f"long run: strang {t_strang:.3f} s, tsit5 {t_tsit_same:.3f} s, dop853 {t_dop:.1f} s")
    results = {}
    for name, (fn, t) in runs.items():
        results[name] = (np.asarray(fn()), t)
    results[f"diffrax Tsit5, fixed h = {h_matched:.3g} (matched wall time)"] = (np.asarray(ms_matched), t_matched)
    results["scipy DOP853, rtol = atol = 1e-10"] = (ms_dop, t_dop)
    rows = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for name, (ms, t) in results.items():
        de, dc = errors(ms)
        # a blown-up run (NaN) counts as an infinite error
        de, dc = np.nan_to_num(de, nan=np.inf), np.nan_to_num(dc, nan=np.inf)
        rows.append({"method": name, "time_s": t, "time_vs_strang": t / t_strang,
                     "max_energy_error": float(de.max()), "final_energy_error": float(de[-1]),
                     "max_casimir_error": float(dc.max()), "final_casimir_error": float(dc[-1]),
                     "casimir_error_at": {f"{ts[k]:.0f}": float(dc[k]) for k in (10, 100, 1000)}})
        axes[0].loglog(ts[1:], np.clip(de[1:], 1e-17, 1e3), label=name, lw=1)
        axes[1].loglog(ts[1:], np.clip(dc[1:], 1e-17, 1e3), label=name, lw=1)
    for ax, what in zip(axes, ("energy", "Casimir |m|²/2")):
        ax.set_xlabel("t")
        ax.set_ylabel(f"relative {what} error")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Rigid body (I = (2, 1, 2/3)), T = {t_end:g}: invariants over a long run")
    out["rows"] = rows
    return out, fig


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def plot(rows, path):
    fig, ax = plt.subplots(figsize=(8.5, 6), constrained_layout=True)
    styles = {"jaxsplit": "-o", "scipy": "--s", "diffrax": ":^"}
    for method in dict.fromkeys(r["method"] for r in rows):
        pts = sorted((r["time_s"], max(r["error"], 1e-16)) for r in rows if r["method"] == method)
        fam = next(r["family"] for r in rows if r["method"] == method)
        ax.loglog(*zip(*pts), styles[fam], label=method, ms=4, lw=1.2)
    ax.set_xlabel("wall time per solve [s] (median, shared 2-core CPU)")
    ax.set_ylabel("max-norm error at T = 10")
    ax.set_title("Work–precision, free rigid body I = (2, 1, 2/3), float64")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke mode: fewer points, T_long = 1e3")
    quick = parser.parse_args(argv).quick
    t_start = time.perf_counter()
    command = "python benchmarks/work_precision.py" + (" --quick" if quick else "")
    out = machine_info(command)
    repeats = 3 if quick else 15
    rows = work_precision(quick, repeats)
    out["work_precision"] = rows
    longrun, fig = long_time(quick)
    out["long_time"] = longrun

    RESULTS.mkdir(exist_ok=True)
    suffix = "-quick" if quick else ""
    plot(rows, RESULTS / f"work_precision{suffix}.png")
    fig.savefig(RESULTS / f"long_time{suffix}.png", dpi=120)

    lines = [
        f"## Work–precision (`{command}`)",
        "",
        f"{out['date_utc']}; {out['machine']}; load average at start "
        f"{', '.join(f'{v:.1f}' for v in out['load_average_at_start'])}; "
        + ", ".join(f"{k} {v}" for k, v in out["versions"].items())
        + f"; jaxsplit at {out['git']}. Median of {repeats} interleaved rounds. "
        f"Plot: `work_precision{suffix}.png`.",
        "",
        "### Error at T = 10 vs wall time",
        "",
        ("Wall time: jaxsplit behind the caller's `jax.jit` (like diffrax here); in brackets the same "
        "run through a plain `jaxsplit.integrate(...).final` call, which adds its Python-side dispatch."),
        "",
        "| method | setting | wall time | max-norm error | rel. Casimir error | work |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        work = (f"{r['rotations']} rotations" if "rotations" in r else
                f"{r['nfev']} f-evals" if "nfev" in r else f"{r['steps']} steps" if "steps" in r else
                f"{r['param'][2:]} steps")
        direct = f" ({r['time_integrate_call_s'] * 1e3:.3g} ms)" if "time_integrate_call_s" in r else ""
        lines.append(f"| {r['method']} | {r['param']} | {r['time_s'] * 1e3:.3g} ms{direct} | {r['error']:.2e} | "
                     f"{r['casimir_error']:.1e} | {work} |")

    targets = (1e-4, 1e-6, 1e-8, 1e-10)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    reach = {m: {t: time_to_reach(rows, m, t) for t in targets} for m in methods}
    out["time_to_reach"] = {m: {f"{t:.0e}": v for t, v in d.items()} for m, d in reach.items()}
    lines += ["", "### Wall time to reach a given error (log-log interpolation; — = not bracketed)", "",
              "| method | " + " | ".join(f"{t:.0e}" for t in targets) + " |",
              "|---|" + "---|" * len(targets)]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join("—" if reach[m][t] is None else f"{reach[m][t] * 1e3:.3g} ms"
                                              for t in targets) + " |")
    ratios = {}
    for fast in ("jaxsplit kahan-li-8 (casimir), scalar+barrier flows",
                 "jaxsplit kahan-li-6 (casimir), scalar+barrier flows",
                 "jaxsplit blanes-moan-s6-prk (casimir), scalar+barrier flows"):
        for slow in ("scipy DOP853", "diffrax Dopri8 (PID)", "diffrax Tsit5 (PID)"):
            for t in targets:
                a, b = reach[fast][t], reach[slow][t]
                if a and b:
                    ratios[f"at error {t:.0e}: {slow} time / {fast} time"] = b / a
    out["speedups"] = ratios
    lines += ["", "Speed-ups (how many times faster the splitting reaches the same error):", ""]
    lines += [f"* {k}: **{v:.3g}×**" for k, v in ratios.items()]

    lines += ["", f"### Long run: T = {longrun['t_end']:g}, h = {longrun['h']} (plot `long_time{suffix}.png`)", "",
              ("| method | wall time | × Strang's time | max rel. energy error | max rel. Casimir error | "
              "rel. Casimir error at t = T/100, T/10, T |"),
              "|---|---|---|---|---|---|"]
    for r in longrun["rows"]:
        at = " / ".join(f"{v:.1e}" for v in r["casimir_error_at"].values())
        lines.append(f"| {r['method']} | {r['time_s']:.3g} s | {r['time_vs_strang']:.3g} | "
                     f"{r['max_energy_error']:.2e} | {r['max_casimir_error']:.2e} | {at} |")
    out["wall_s"] = time.perf_counter() - t_start
    lines += ["", f"Total wall time of the script: {out['wall_s']:.0f} s."]
    (RESULTS / f"work_precision{suffix}.json").write_text(json.dumps(out, indent=1))
    (RESULTS / f"work_precision{suffix}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
