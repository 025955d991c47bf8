"""What going through diffrax costs, and what its dense output does to the invariants.

Standard case (I = (2, 1, 2/3), m0 = (cos 1.1, 0, sin 1.1), float64, Casimir split, shift
axis 1). Side by side in one process, repetitions interleaved round-robin (``_common``):

(a) overhead: ``diffrax.diffeqsolve(jd.term(...), jd.Splitting(scheme), ...)`` against
    ``jaxsplit.integrate(jaxsplit.splitting(...), ...)``, both compiled ahead of time, same
    scheme and steps; final state only, and output at 50 times (``SaveAt(ts=)`` / ``ts=``);
    Strang (2 rotations a step: the loop's overhead shows) and Kahan–Li 6; compile times;
(b) dense output at 50 random times, h = 0.1: the partial step (``jd.PartialStep``) against
    diffrax's cubic Hermite interpolant and linear interpolation between the same grid states:
    Casimir drift and error against a tight reference;
(c) gradients (inertia and m0) through ``diffeqsolve`` with the default, a checkpointed
    (``checkpoints=10``) and the direct adjoint, against ``integrate``'s (relative difference);
(d) the time grid: final-state difference diffrax vs integrate at a dyadic h (grids equal)
    and at h = 0.1 (diffrax's grid t0 + (t1 - t0) k / n differs from k h by ulps);
(e) adaptive steps: ``diffrax.HalfSolver(jd.Splitting)`` with a PID controller over T = 1000,
    energy and Casimir drift against fixed steps of the same average size;
(f) diffrax's own cost of ``SaveAt(ts=)``: ``diffrax.Euler`` on a linear ODE, same steps, final
    state only against 50 output times (no jaxsplit involved).

    python benchmarks/diffrax_overhead.py            # full run (~2 min on 2 shared cores)
    python benchmarks/diffrax_overhead.py --quick    # smoke mode

Writes ``benchmarks/results/diffrax_overhead{,-quick}.{json,md}``.
"""

import argparse
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
from _common import aot, fmt, interleaved, machine_info, paired_ratio, ready, write

import jaxsplit
import jaxsplit.diffrax as jd

CASE = jaxsplit.STANDARD_CASE
INERTIA = jnp.asarray(CASE.inertia)
M0 = jnp.asarray(CASE.m0)
SHIFT = 1


def log(msg: str):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def casimir_drift(ms):
    return float(jnp.max(jnp.abs(jnp.sum(ms * ms, axis=-1) / jnp.sum(M0 * M0) - 1)))


def via_diffrax(scheme, n, h, ts=None, adjoint=None):
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)
    extra = {} if adjoint is None else {"adjoint": adjoint}

    def run(m0, inertia):
        term = jd.term(jaxsplit.RigidBody(inertia, allow_nonphysical=True), split="casimir", shift=SHIFT)
        return diffrax.diffeqsolve(term, jd.Splitting(scheme), 0.0, n * h, h, m0, saveat=saveat,
                                   max_steps=n, **extra).ys
    return run


def via_integrate(scheme, n, h, ts=None):
    def run(m0, inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia, allow_nonphysical=True), scheme, "casimir", shift=SHIFT)
        if ts is None:
            return jaxsplit.integrate(step, m0, h, n).final[None]
        return jaxsplit.integrate(step, m0, h, ts=ts).x
    return run


def overhead(n: int, repeats: int) -> list[dict]:
    h = 10.0 / n
    ts = jnp.sort(jax.random.uniform(jax.random.PRNGKey(0), (50,), minval=0.0, maxval=n * h))
    rows = []
    for scheme in ("strang", "kahan-li-6"):
        for label, t in (("final state", None), ("50 output times", ts)):
            d, d_compile = aot(via_diffrax(scheme, n, h, t), M0, INERTIA)
            i, i_compile = aot(via_integrate(scheme, n, h, t), M0, INERTIA)
            diff = float(jnp.max(jnp.abs(d(M0, INERTIA) - i(M0, INERTIA))))
            times = interleaved({"diffrax": ready(d, M0, INERTIA), "integrate": ready(i, M0, INERTIA)}, repeats)
            rows.append({"scheme": scheme, "output": label, "steps": n,
                         "diffrax_s": statistics.median(times["diffrax"]),
                         "integrate_s": statistics.median(times["integrate"]),
                         "ratio": paired_ratio(times, "diffrax", "integrate"),
                         "compile_diffrax_s": d_compile, "compile_integrate_s": i_compile, "max_diff": diff})
            log(f"{scheme} {label}: ratio {rows[-1]['ratio']:.2f}")
    return rows


def dense_output() -> dict:
    h, n = 0.1, 100
    ts = jnp.sort(jax.random.uniform(jax.random.PRNGKey(1), (50,), minval=0.0, maxval=10.0))
    term = jd.term(jaxsplit.RigidBody(INERTIA, allow_nonphysical=True), split="casimir", shift=SHIFT)
    solver = jd.Splitting("kahan-li-6")
    partial = diffrax.diffeqsolve(term, solver, 0.0, 10.0, h, M0, saveat=diffrax.SaveAt(ts=ts)).ys
    grid = diffrax.diffeqsolve(term, solver, 0.0, 10.0, h, M0, saveat=diffrax.SaveAt(t0=True, steps=True)).ys[: n + 1]
    k = jnp.minimum(jnp.floor(ts / h).astype(int), n - 1)
    s = ts - k * h
    body = jaxsplit.RigidBody(INERTIA, allow_nonphysical=True)

    def hermite(t, y0, y1):
        return diffrax.ThirdOrderHermitePolynomialInterpolation(
            t0=0.0, t1=h, y0=y0, y1=y1, k0=h * body.vector_field(y0), k1=h * body.vector_field(y1)).evaluate(t)

    cubic = jax.vmap(hermite)(s, grid[k], grid[k + 1])
    linear = grid[k] + (s / h)[:, None] * (grid[k + 1] - grid[k])
    tight = jaxsplit.integrate(jaxsplit.splitting(body, "kahan-li-10", "casimir", shift=SHIFT), M0, 0.001, ts=ts).x
    out = {}
    for name, ys in (("partial step (jd.PartialStep)", partial), ("cubic Hermite", cubic), ("linear", linear)):
        out[name] = {"casimir_drift": casimir_drift(ys), "error": float(jnp.max(jnp.abs(ys - tight)))}
    return out


def gradients() -> dict:
    n, h = 100, 0.1

    def loss(run):
        return lambda inertia, m0: jnp.sum(jnp.sin(run(m0, inertia)[-1]))

    ref = jax.jit(jax.grad(loss(via_integrate("kahan-li-6", n, h)), argnums=(0, 1)))(INERTIA, M0)
    out = {}
    for name, adjoint in (("RecursiveCheckpointAdjoint() (default)", diffrax.RecursiveCheckpointAdjoint()),
                          ("RecursiveCheckpointAdjoint(checkpoints=10)", diffrax.RecursiveCheckpointAdjoint(10)),
                          ("DirectAdjoint()", diffrax.DirectAdjoint())):
        g = jax.jit(jax.grad(loss(via_diffrax("kahan-li-6", n, h, adjoint=adjoint)), argnums=(0, 1)))(INERTIA, M0)
        out[name] = max(float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b))) for a, b in zip(g, ref))
    return out


def time_grid() -> dict:
    out = {}
    for h, n in ((0.125, 80), (0.1, 100)):
        d = via_diffrax("kahan-li-6", n, h)(M0, INERTIA)[-1]
        i = via_integrate("kahan-li-6", n, h)(M0, INERTIA)[-1]
        out[f"h = {h}"] = float(jnp.max(jnp.abs(d - i)))
    return out


def adaptive(t_end: float) -> dict:
    body = jaxsplit.RigidBody(INERTIA, allow_nonphysical=True)
    term = jd.term(body, split="casimir", shift=SHIFT)
    ts = jnp.linspace(0.0, t_end, 201)
    sol = diffrax.diffeqsolve(term, diffrax.HalfSolver(jd.Splitting("strang")), 0.0, t_end, 0.1, M0,
                              saveat=diffrax.SaveAt(ts=ts), max_steps=10**6,
                              stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-4))
    steps = int(sol.stats["num_accepted_steps"])
    fixed = diffrax.diffeqsolve(term, jd.Splitting("strang"), 0.0, t_end, t_end / steps, M0,
                                saveat=diffrax.SaveAt(ts=ts), max_steps=10**6)
    e0 = body.hamiltonian(M0)

    def energy(ys):
        e = jax.vmap(body.hamiltonian)(ys) / e0 - 1
        return {"max_energy_error": float(jnp.max(jnp.abs(e))), "energy_error_at_end": float(e[-1]),
                "casimir_drift": casimir_drift(ys)}

    return {"T": t_end, "accepted_steps": steps, "rejected_steps": int(sol.stats["num_rejected_steps"]),
            "HalfSolver + PID(rtol=atol=1e-4)": energy(sol.ys), "fixed steps, same count": energy(fixed.ys)}


def saveat_cost(n: int, repeats: int) -> dict:
    term = diffrax.ODETerm(lambda t, y, args: jnp.stack([y[1], -y[0], 0 * y[2]]))
    ts = jnp.linspace(0.0, 10.0, 50)
    runs = {}
    for name, saveat in (("final state", diffrax.SaveAt(t1=True)), ("50 output times", diffrax.SaveAt(ts=ts))):
        def run(y, saveat=saveat):
            return diffrax.diffeqsolve(term, diffrax.Euler(), 0.0, 10.0, 10.0 / n, y, saveat=saveat, max_steps=n).ys
        compiled, _ = aot(run, M0)
        runs[name] = ready(compiled, M0)
    times = interleaved(runs, repeats)
    return {"steps": n, **{k: statistics.median(v) for k, v in times.items()},
            "ratio": paired_ratio(times, "50 output times", "final state")}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke mode: fewer steps and repeats")
    args = parser.parse_args(argv)
    n, repeats, t_end = (2000, 3, 100.0) if args.quick else (20000, 9, 1000.0)
    command = "python benchmarks/diffrax_overhead.py" + (" --quick" if args.quick else "")
    out = {"info": machine_info(command), "overhead": overhead(n, repeats)}
    log("dense output")
    out["dense_output"] = dense_output()
    log("gradients")
    out["gradients"] = gradients()
    out["time_grid"] = time_grid()
    log("adaptive")
    out["adaptive"] = adaptive(t_end)
    out["saveat_cost"] = saveat_cost(n, repeats)
    out["info"]["versions"]["diffrax"] = diffrax.__version__

    lines = [f"# diffrax overhead ({out['info']['date_utc']})", "", (f"`{command}`; {out['info']['machine']}; "
              f"git {out['info']['git']}; diffrax {diffrax.__version__}, jax {jax.__version__}."), "",
             "## (a) Wall time, diffrax vs integrate (ratio = median of per-round ratios)", "",
             "| scheme | output | steps | diffrax | integrate | ratio | compile diffrax / integrate | max diff |",
             "|---|---|---|---|---|---|---|---|"]
    for r in out["overhead"]:
        lines.append(f"| {r['scheme']} | {r['output']} | {r['steps']} | {fmt(r['diffrax_s'])} | {fmt(r['integrate_s'])}"
                     f" | **{r['ratio']:.2f}** | {fmt(r['compile_diffrax_s'])} / {fmt(r['compile_integrate_s'])}"
                     f" | {r['max_diff']:.1e} |")
    lines += ["", "## (b) Dense output at 50 random times, Kahan–Li 6, h = 0.1", "",
              "| interpolation | Casimir drift | error vs tight reference |", "|---|---|---|"]
    for name, r in out["dense_output"].items():
        lines.append(f"| {name} | {r['casimir_drift']:.1e} | {r['error']:.1e} |")
    lines += ["", "## (c) Gradients through diffeqsolve vs through integrate (relative)", "",
              "| adjoint | max relative difference |", "|---|---|"]
    lines += [f"| {k} | {v:.1e} |" for k, v in out["gradients"].items()]
    lines += ["", "## (d) Final state, diffrax vs integrate, by time grid", "", "| step | max diff |", "|---|---|"]
    lines += [f"| {k} | {v:.1e} |" for k, v in out["time_grid"].items()]
    a = out["adaptive"]
    lines += ["", (f"## (e) Adaptive steps, Strang, T = {a['T']:g} ({a['accepted_steps']} accepted, "
                   f"{a['rejected_steps']} rejected)"), "",
              "| run | max energy error | energy error at T | Casimir drift |", "|---|---|---|---|"]
    for name in ("HalfSolver + PID(rtol=atol=1e-4)", "fixed steps, same count"):
        r = a[name]
        lines.append(f"| {name} | {r['max_energy_error']:.1e} | {r['energy_error_at_end']:.1e} | "
                     f"{r['casimir_drift']:.1e} |")
    c = out["saveat_cost"]
    lines += ["", f"## (f) diffrax's own SaveAt(ts) cost: diffrax.Euler, {c['steps']} steps", "",
              "| output | time |", "|---|---|",
              f"| final state | {fmt(c['final state'])} |", f"| 50 output times | {fmt(c['50 output times'])} |",
              f"| ratio | **{c['ratio']:.1f}** |"]
    write("diffrax_overhead", args.quick, out, lines)


if __name__ == "__main__":
    main()
