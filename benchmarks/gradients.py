"""What does a gradient through n steps cost in memory and time, per adjoint?

``integrate(..., adjoint=)`` with ``"store"`` (one state in 16 steps kept; under ``jax.grad``
the steps walked back from each), ``"checkpoint"``
(√n blocks) and ``"reversible"`` (states rebuilt by stepping back, fused rotation
pullbacks) on

* the free body: Strang, Casimir split; gradient with respect to the inertia and m0 (the
  inertia is traced, so the run keeps the general cos/sin kernel);
* a heavy top: rotations of (m, Γ) and the gravity kick m ← m + t·w·Γ×χ (Strang on the axes
  split plus the kick). The Lagrange top (I1 = I2, χ on the symmetry axis: integrable) for
  agreement and time, one top and 10³ tops at once; an asymmetric top (chaotic) to show
  what its dynamics do to round-off: its stored gradient itself grows like e^{λt}.

The loss is a weighted sum of the final state; gradients with respect to every parameter
and the initial state.

* memory: XLA's own account of the compiled gradient (``memory_analysis().temp_size_in_bytes``);
* time: gradient / forward CPU time of the process (median of the per-round ratios,
  interleaved rounds; the wall time moved with other jobs' load on the 2 shared cores),
  the stored one also as ``jax.jit(jax.grad(jax.jit(loss)))``, where the call sees no reverse
  mode and the differentiated scan runs (the stored gradient before 04106fc);
* agreement: max relative difference from the stored-trajectory gradient.

A profile splits the heavy top's backward pass by kind of flow (rotations of m alone,
rotations of (m, Γ), one rotation and the kick): time per step of the forward run and of
the backward pass (gradient minus forward).

A table measures the stored adjoint keeping one state in k steps (``_adjoints.KEEP_EVERY``,
16 in the library; k = 1 keeps every state, as before): memory, time against the forward run,
and the gradient's difference from keeping every state and from the differentiated scan.

A last table answers which gradient ``fit`` should use: its model (200 observation
intervals of 2 Kahan–Li 6 steps each) with the per-interval checkpoint and rolled word it
uses, against the unrolled word with each adjoint per interval: time per loss gradient and
compile time.

    python benchmarks/gradients.py [--quick]

Writes ``benchmarks/results/gradients.{md,json}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, interleaved, log, machine_info

import jaxsplit
from jaxsplit.core import _adjoints
from jaxsplit.core._adjoints import advance
from jaxsplit.core._compose import roll
from jaxsplit.explore._fit_inertia import _body

ADJOINTS = ("store", "checkpoint", "reversible")
SCAN = "store, grad of a jit"  # the differentiated scan (the call sees no reverse mode)
H = 0.01
WEIGHTS = jnp.arange(1.0, 4.0)


def free_body():
    args = (jnp.asarray(jaxsplit.STANDARD_CASE.inertia), jnp.asarray(jaxsplit.STANDARD_CASE.m0))

    def loss(adjoint, n):
        def f(inertia, m):
            step = jaxsplit.splitting(jaxsplit.RigidBody(inertia, allow_nonphysical=True), "strang", "casimir", shift=1)
            return jnp.sum(jaxsplit.integrate(step, m, H, n, adjoint=adjoint).final * WEIGHTS)
        return f

    return loss, args


def heavy_top(inertia, chi, bodies=None):
    if bodies is None:
        x0 = (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97]))
    else:
        keys = jax.random.split(jax.random.PRNGKey(0))
        gamma = jax.random.normal(keys[1], (bodies, 3))
        x0 = (jax.random.normal(keys[0], (bodies, 3)), gamma / jnp.linalg.norm(gamma, axis=1, keepdims=True))
    args = (jnp.asarray(inertia), jnp.asarray(chi), jnp.asarray(1.5), x0)

    def loss(adjoint, n):
        def f(inertia, chi, weight, x0):
            step = jaxsplit.splitting(jaxsplit.heavy_top(inertia, chi, weight), "strang")  # axes split
            m, gamma = jaxsplit.integrate(step, x0, H, n, adjoint=adjoint).final
            return jnp.sum(m * WEIGHTS) + jnp.sum(gamma**3)
        return f

    return loss, args


SYSTEMS = {
    "free body": free_body,
    "Lagrange top": lambda: heavy_top([1.0, 1.0, 0.6], [0.0, 0.0, 0.3]),
    "Lagrange top, 10³ at once": lambda: heavy_top([1.0, 1.0, 0.6], [0.0, 0.0, 0.3], bodies=1000),
    "asymmetric top (chaotic)": lambda: heavy_top([1.0, 1.2, 0.6], [0.0, 0.05, 0.3]),
}


def relative(a, b):
    return max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y)))
               for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)))


def largest(tree):
    return max(float(jnp.max(jnp.abs(x))) for x in jax.tree_util.tree_leaves(tree))


def gradient(loss, adjoint, n, args):
    return jax.jit(jax.grad(loss(adjoint, n), argnums=tuple(range(len(args)))))


def memory_and_agreement(system, counts, run_up_to):
    loss, args = SYSTEMS[system]()
    rows = []
    for n in counts:
        row = {"system": system, "n_steps": n}
        grads = {}
        for adjoint in ADJOINTS:
            fn = gradient(loss, adjoint, n, args)
            row[f"{adjoint}_temp_bytes"] = int(fn.lower(*args).compile().memory_analysis().temp_size_in_bytes)
            if n <= run_up_to:
                grads[adjoint] = fn(*args)
        if grads:
            row["largest_gradient"] = largest(grads["store"])
            for adjoint in ("checkpoint", "reversible"):
                row[f"{adjoint}_vs_store"] = relative(grads[adjoint], grads["store"])
        log(f"{system}, n = {n}: memory {[row[f'{a}_temp_bytes'] for a in ADJOINTS]}")
        rows.append(row)
    return rows


def time_ratios(system, n, repeats):
    loss, args = SYSTEMS[system]()
    forward = jax.jit(loss("store", n))
    cases = {"forward": lambda: jax.block_until_ready(forward(*args))}
    for adjoint in ADJOINTS:
        fn = gradient(loss, adjoint, n, args)
        jax.block_until_ready(fn(*args))
        cases[adjoint] = lambda fn=fn: jax.block_until_ready(fn(*args))
    # "store" as the differentiated scan: grad of the user's own jit hides reverse mode from the call
    hidden = jax.jit(jax.grad(jax.jit(loss("store", n)), argnums=tuple(range(len(args)))))
    jax.block_until_ready(hidden(*args))
    cases[SCAN] = lambda: jax.block_until_ready(hidden(*args))
    cases["forward"]()
    log(f"{system}: timing at {n} steps")
    times = interleaved(cases, repeats, clock=time.process_time)
    out = {"system": system, "n_steps": n, "forward_s": statistics.median(times["forward"])}
    for adjoint in ADJOINTS + (SCAN,):
        out[adjoint] = statistics.median(a / f for a, f in zip(times[adjoint], times["forward"]))
    return out


# ------------------------------------------------------------------ the stored adjoint's interval
KEEP_EVERY = (1, 4, 16, 64)


def keep_every(system, n, repeats):
    """The stored gradient keeping one state in k steps, for each k of ``KEEP_EVERY``: memory,
    time / forward (``repeats`` rounds; none: not timed), relative difference from k = 1 and
    from the differentiated scan. ``integrate``'s jit traced the stored adjoint with the
    library's interval: its caches are cleared for each k (the programs are compiled ahead)."""
    loss, args = SYSTEMS[system]()
    argnums = tuple(range(len(args)))
    forward = jax.jit(loss("store", n)).lower(*args).compile()
    scan = jax.jit(jax.grad(jax.jit(loss("store", n)), argnums=argnums))(*args)
    cases, rows, grads = {"forward": lambda: jax.block_until_ready(forward(*args))}, [], {}
    default = _adjoints.KEEP_EVERY
    try:
        for k in KEEP_EVERY:
            _adjoints.KEEP_EVERY = k
            jax.clear_caches()
            fn = gradient(loss, "store", n, args).lower(*args).compile()
            grads[k] = fn(*args)
            rows.append({"system": system, "n_steps": n, "keep_every": k,
                         "temp_bytes": int(fn.memory_analysis().temp_size_in_bytes),
                         "vs_every_state": relative(grads[k], grads[1]), "vs_scan": relative(grads[k], scan)})
            cases[k] = lambda fn=fn: jax.block_until_ready(fn(*args))
    finally:
        _adjoints.KEEP_EVERY = default
        jax.clear_caches()
    if repeats:
        log(f"{system}: timing the stored adjoint's interval at {n} steps")
        for fn in cases.values():
            fn()
        times = interleaved(cases, repeats, clock=time.process_time)
        for row in rows:
            row["time_vs_forward"] = statistics.median(
                a / f for a, f in zip(times[row["keep_every"]], times["forward"]))
    return rows


# ------------------------------------------------------------------ profile of the top
PROFILE = {"3 rotations of m (axes split)": ("m", 3, False), "3 rotations of (m, Γ)": ("m, Γ", 3, False),
           "1 rotation of (m, Γ) and the kick": ("m, Γ", 1, True), "3 rotations of (m, Γ) and the kick (the top)":
           ("m, Γ", 3, True)}


def profile(n, repeats):
    """Forward and backward time per step of Strang over the given flows, one top."""
    x0 = (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97]))
    args = (jnp.array([1.0, 1.0, 0.6]), jnp.array([0.0, 0.0, 0.3]), jnp.asarray(1.5))
    cases = {}
    for name, (state, rotations, kick) in PROFILE.items():
        def loss(inertia, chi, weight, x, adjoint, state=state, rotations=rotations, kick=kick):
            parts = None if state == "m" else ("momentum", "vector")
            flows = tuple(jaxsplit.AxisRotation(k, 1 / inertia[k], parts) for k in range(rotations))
            flows += (jaxsplit.heavy_top(inertia, chi, weight).kick(),) if kick else ()
            y = jaxsplit.integrate(jaxsplit.compose(flows, "strang"), x if parts else x[0], H, n, adjoint=adjoint).final
            return sum(jnp.sum(leaf * WEIGHTS) for leaf in jax.tree_util.tree_leaves(y))

        forward = jax.jit(lambda *a, loss=loss: loss(*a, "store"))
        backward = jax.jit(jax.grad(lambda *a, loss=loss: loss(*a, "reversible"), argnums=(0, 1, 2, 3)))
        for key, fn in (("forward", forward), ("gradient", backward)):
            jax.block_until_ready(fn(*args, x0))
            cases[name, key] = lambda fn=fn: jax.block_until_ready(fn(*args, x0))
    log("profile of the top: timing")
    times = interleaved(cases, repeats)
    rows = []
    for name in PROFILE:
        f, g = statistics.median(times[name, "forward"]), statistics.median(times[name, "gradient"])
        rows.append({"flows": name, "forward_ns_per_step": f / n * 1e9, "backward_ns_per_step": (g - f) / n * 1e9,
                     "gradient_vs_forward": statistics.median(
                         a / b for a, b in zip(times[name, "gradient"], times[name, "forward"]))})
    return rows


# ------------------------------------------------------------------ fit's model
FIT_VARIANTS = ("rolled word, checkpoint per interval (fit today)", "unrolled, checkpoint per interval",
                "unrolled, store", "unrolled, reversible per interval")


def fit_model(variant, n_sub=2, scheme="kahan-li-6"):
    """fit's predict on the free body: the state after every interval of ``dts``."""
    def predict(log_inertia, m0, dts):
        step = jaxsplit.splitting(_body(log_inertia), scheme, "casimir", shift=1)
        if variant == FIT_VARIANTS[0]:
            rolled = roll(step)

            @jax.checkpoint
            def interval(x, dt):
                x = jax.lax.fori_loop(0, n_sub, lambda _, y: rolled(y, dt / n_sub), x)
                return x, x
        elif variant == FIT_VARIANTS[1]:
            @jax.checkpoint
            def interval(x, dt):
                x = step.advance(x, dt / n_sub, n_sub)
                return x, x
        else:
            adjoint = "store" if variant == FIT_VARIANTS[2] else "reversible"

            def interval(x, dt):
                x = advance(step, x, dt / n_sub, n_sub, adjoint)
                return x, x
        return jax.lax.scan(interval, m0, dts)[1]

    return predict


def fit_timing(repeats):
    dts = jnp.asarray(np.diff(np.linspace(0.0, 20.0, 201)))
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)
    log_inertia = jnp.log(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    observed = fit_model(FIT_VARIANTS[2])(log_inertia + 0.01, m0, dts)
    cases, compile_s, grads = {}, {}, {}
    for variant in FIT_VARIANTS:
        predict = fit_model(variant)
        fn = jax.jit(jax.value_and_grad(lambda li, m, predict=predict: jnp.mean((predict(li, m, dts) - observed) ** 2),
                                        argnums=(0, 1)))
        t0 = time.perf_counter()
        fn.lower(log_inertia, m0).compile()
        compile_s[variant] = time.perf_counter() - t0
        grads[variant] = jax.block_until_ready(fn(log_inertia, m0))
        cases[variant] = lambda fn=fn: jax.block_until_ready(fn(log_inertia, m0))
    log("fit model: timing")
    times = interleaved(cases, repeats)
    base = FIT_VARIANTS[0]
    return [{"variant": v, "gradient_s": statistics.median(times[v]), "compile_s": compile_s[v],
             "time_vs_fit_today": statistics.median(a / b for a, b in zip(times[v], times[base])),
             "vs_fit_today": relative(grads[v], grads[base])} for v in FIT_VARIANTS]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/gradients.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    counts = (1_000, 10_000) if quick else (1_000, 10_000, 100_000, 1_000_000)
    timed = 10_000 if quick else 100_000
    repeats = 3 if quick else 5
    rows = []
    for system in ("free body", "Lagrange top", "asymmetric top (chaotic)"):
        rows += memory_and_agreement(system, counts, timed)
    ratios = [time_ratios(system, timed, repeats) for system in ("free body", "Lagrange top")]
    ratios.append(time_ratios("Lagrange top, 10³ at once", timed // 100, repeats))
    interval_rows = (keep_every("Lagrange top, 10³ at once", timed // 100, repeats)
                     + keep_every("free body", timed, repeats)
                     + keep_every("asymmetric top (chaotic)", counts[1], 0))
    profile_rows = profile(timed, repeats)
    fit_rows = fit_timing(3 if quick else 7)
    out.update(rows=rows, time_vs_forward=ratios, keep_every=interval_rows, profile=profile_rows, fit=fit_rows)

    lines = header(out, "Gradients through n steps (`benchmarks/gradients.py`)")
    lines += [("XLA temporary memory of the compiled gradient (MiB); where run, the largest gradient entry and the "
              "largest relative difference from the stored-trajectory gradient."), "",
              ("| system | steps | store | checkpoint | reversible | max gradient | checkpoint vs store | "
              "reversible vs store |"), "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        mib = [f"{r[f'{a}_temp_bytes'] / 2**20:.3g}" for a in ADJOINTS]
        extra = [f"{r[k]:.1e}" if k in r else "—" for k in ("largest_gradient", "checkpoint_vs_store",
                                                              "reversible_vs_store")]
        lines.append(f"| {r['system']} | {r['n_steps']:,} | " + " | ".join(mib + extra) + " |")
    lines += ["", f"CPU time of one gradient / one forward run (median of {repeats} interleaved rounds):", "",
              ("| system | steps | forward | store | checkpoint | reversible | store, `grad(jit(loss))` (the "
               "differentiated scan) |"), "|---|---|---|---|---|---|---|"]
    for r in ratios:
        lines.append(f"| {r['system']} | {r['n_steps']:,} | {r['forward_s'] * 1e3:.3g} ms | "
                     + " | ".join(f"{r[a]:.2f}×" for a in ADJOINTS + (SCAN,)) + " |")
    lines += ["", (f"The stored adjoint keeping one state in k steps (the library keeps one in "
                   f"{_adjoints.KEEP_EVERY}; k = 1: every state): XLA temporary memory of the compiled gradient, "
                   f"CPU time of one gradient / one forward run (median of {repeats} interleaved rounds), and the "
                   "largest relative difference from keeping every state and from the differentiated scan "
                   "(`grad(jit(loss))`)."), "",
              "| system | steps | k | memory (MiB) | gradient / forward | vs every state | vs the scan |",
              "|---|---|---|---|---|---|---|"]
    for r in interval_rows:
        timed_k = f"{r['time_vs_forward']:.2f}×" if "time_vs_forward" in r else "—"
        lines.append(f"| {r['system']} | {r['n_steps']:,} | {r['keep_every']} | {r['temp_bytes'] / 2**20:.3g} | "
                     f"{timed_k} | {r['vs_every_state']:.1e} | {r['vs_scan']:.1e} |")
    lines += ["", (f"Profile of one top, Strang over the flows named, {timed:,} steps (ns per step; backward = gradient "
              "− forward):"), "", "| flows | forward | backward | gradient / forward |", "|---|---|---|---|"]
    for r in profile_rows:
        lines.append(f"| {r['flows']} | {r['forward_ns_per_step']:.0f} | {r['backward_ns_per_step']:.0f} | "
                     f"{r['gradient_vs_forward']:.2f}× |")
    lines += ["", ("fit's loss gradient (free body, 200 intervals × 2 Kahan–Li 6 steps, gradient with respect to "
              "log I and m0):"), "", "| model | per gradient | × fit today | compile | vs fit today |",
              "|---|---|---|---|---|"]
    for r in fit_rows:
        lines.append(f"| {r['variant']} | {r['gradient_s'] * 1e3:.3g} ms | {r['time_vs_fit_today']:.2f} | "
                     f"{r['compile_s']:.2g} s | {r['vs_fit_today']:.0e} |")
    finish("gradients", out, lines, start, quick)


if __name__ == "__main__":
    main()
