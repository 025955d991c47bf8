"""Steady-state throughput of jaxsplit's composed steps against peers, side by side.

Standard case (I = (2, 1, 2/3), m0 = (cos 1.1, 0, sin 1.1), float64, h = 0.01). Every
contender is run in this one process, repetitions interleaved round-robin, and the
median of the repeats is reported; ratios are medians of the per-round paired ratios,
so a burst of load from other jobs on the (shared, 2-core) machine hits both sides.

(a) single trajectory, ``n`` steps: jaxsplit Strang (axes and casimir split), Kahan–Li 6,
    through ``jaxsplit.splitting`` as the working tree has it and through the library's
    generic composer with the rotation form pinned (``_common.step_variant``: 3x3 matrix,
    two-component, correction form, each optionally behind an optimization barrier);
(b) a hand-fused JAX loop (``lax.fori_loop`` over three scalars, the same merged Strang
    rotations written inline as cos/sin updates, no matrices) — the cost of the generic
    composer; and a fusion probe: one jitted step per rotation form (time, XLA fusions);
(c) NumPy: the Strang rotations in a Python loop on numpy scalars (and on Python floats
    with ``math``), and vectorised over a batch;
(d) batched throughput: ``jax.vmap`` over B = 1, 64, 1024, 16384 initial conditions,
    in states·steps per second;
(e) compile time (trace + lower + XLA compile, ``jit(...).lower(...).compile()``),
    reported separately from run time.

    python benchmarks/throughput.py            # full run, < 3 min on 2 shared cores
    python benchmarks/throughput.py --quick    # smoke mode

Writes ``benchmarks/results/throughput{,-quick}.{json,md}``.
"""

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import aot, fmt, interleaved, machine_info, paired_ratio, ready, step_variant

import jaxsplit

RESULTS = Path(__file__).resolve().parent / "results"
CASE = jaxsplit.STANDARD_CASE
INERTIA = np.asarray(CASE.inertia)
M0 = np.asarray(CASE.m0)
H = 0.01
SHIFT = 1  # the middle-1/I axis of (2, 1, 2/3) (0-based): what shift="auto" picks
BATCHES = (1, 64, 1024, 16384)


# ---------------------------------------------------------------------------------------
# contenders: every jitted one takes (m0, h, inertia) so nothing is baked in as a constant


def jaxsplit_run(scheme: str, split: str, n: int):
    def run(m0, h, inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), scheme, split, **({"shift": SHIFT} if split == "casimir" else {}))
        return jaxsplit.integrate(step, m0, h, n).final

    return run


def _rot(x, y, theta, cos, sin):
    """Rotation of the (x, y) pair by theta: x <- c x + s y, y <- -s x + c y."""
    c, s = cos(theta), sin(theta)
    return c * x + s * y, -s * x + c * y


def fused_strang_axes(n: int):
    """Hand-fused 3-part Strang, first-same-as-last merged: 4 rotations per step.

    Word per step: axis 1 (h/2), axis 2 (h), axis 1 (h/2), axis 0 (h); the run starts with
    axis 0 (h/2) and ends with axis 0 (h/2) instead of h — exactly jaxsplit's sequence.
    Axis k rotates (m_i, m_j), (i, j) following k cyclically, by angle m_k t / I_k.
    """

    def run(m0, h, inertia):
        a0, a1, a2 = 1 / inertia[0], 1 / inertia[1], 1 / inertia[2]
        cos, sin = jnp.cos, jnp.sin

        def r0(m, t):
            x, y, z = m
            y, z = _rot(y, z, a0 * x * t, cos, sin)
            return x, y, z

        def r1(m, t):
            x, y, z = m
            z, x = _rot(z, x, a1 * y * t, cos, sin)
            return x, y, z

        def r2(m, t):
            x, y, z = m
            x, y = _rot(x, y, a2 * z * t, cos, sin)
            return x, y, z

        def body(_, m):
            return r0(r1(r2(r1(m, h / 2), h), h / 2), h)

        m = r0((m0[0], m0[1], m0[2]), h / 2)
        m = jax.lax.fori_loop(0, n - 1, body, m)
        m = r0(r1(r2(r1(m, h / 2), h), h / 2), h / 2)
        return jnp.stack(m)

    return run


def fused_strang_casimir(n: int):
    """Hand-fused 2-part (Casimir-shifted, shift axis 1) Strang: 2 rotations per step."""

    def run(m0, h, inertia):
        c0 = 1 / inertia[0] - 1 / inertia[SHIFT]
        c2 = 1 / inertia[2] - 1 / inertia[SHIFT]
        cos, sin = jnp.cos, jnp.sin

        def r0(m, t):
            x, y, z = m
            y, z = _rot(y, z, c0 * x * t, cos, sin)
            return x, y, z

        def r2(m, t):
            x, y, z = m
            x, y = _rot(x, y, c2 * z * t, cos, sin)
            return x, y, z

        m = r0((m0[0], m0[1], m0[2]), h / 2)
        m = jax.lax.fori_loop(0, n - 1, lambda _, m: r0(r2(m, h), h), m)
        m = r0(r2(m, h), h / 2)
        return jnp.stack(m)

    return run


def log(msg: str):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def variant_run(scheme: str, split: str, variant: str, n: int):
    """``n`` steps of a ``_common.step_variant`` step through ``jaxsplit.integrate``."""

    def run(m0, h, inertia):
        step = step_variant(jaxsplit.RigidBody(inertia), scheme, split, variant, SHIFT)
        return jaxsplit.integrate(step, m0, h, n).final

    return run


# NumPy -----------------------------------------------------------------------------------


def numpy_scalar_strang(n: int, m0, h, inertia, cos=np.cos, sin=np.sin, scalar=np.float64):
    """Strang (axes, merged as above) in a Python loop on scalars: numpy or Python floats."""
    a0, a1, a2 = (scalar(1 / v) for v in inertia)
    x, y, z = (scalar(v) for v in m0)
    h = scalar(h)
    hh = h / 2

    def r0(x, y, z, t):
        th = a0 * x * t
        c, s = cos(th), sin(th)
        return x, c * y + s * z, -s * y + c * z

    def r1(x, y, z, t):
        th = a1 * y * t
        c, s = cos(th), sin(th)
        return -s * z + c * x, y, c * z + s * x

    def r2(x, y, z, t):
        th = a2 * z * t
        c, s = cos(th), sin(th)
        return c * x + s * y, -s * x + c * y, z

    x, y, z = r0(x, y, z, hh)
    for _ in range(n - 1):
        x, y, z = r0(*r1(*r2(*r1(x, y, z, hh), h), hh), h)
    x, y, z = r0(*r1(*r2(*r1(x, y, z, hh), h), hh), hh)
    return np.array([x, y, z])


def numpy_batch_strang(n: int, m0s, h, inertia):
    """The same rotations vectorised over a batch of states (arrays of shape (B,))."""
    a0, a1, a2 = (1 / v for v in inertia)
    x, y, z = (np.array(m0s[:, k]) for k in range(3))
    hh = h / 2

    def r0(x, y, z, t):
        th = (a0 * t) * x
        c, s = np.cos(th), np.sin(th)
        return x, c * y + s * z, c * z - s * y

    def r1(x, y, z, t):
        th = (a1 * t) * y
        c, s = np.cos(th), np.sin(th)
        return c * x - s * z, y, c * z + s * x

    def r2(x, y, z, t):
        th = (a2 * t) * z
        c, s = np.cos(th), np.sin(th)
        return c * x + s * y, c * y - s * x, z

    x, y, z = r0(x, y, z, hh)
    for _ in range(n - 1):
        x, y, z = r0(*r1(*r2(*r1(x, y, z, hh), h), hh), h)
    x, y, z = r0(*r1(*r2(*r1(x, y, z, hh), h), hh), hh)
    return np.stack([x, y, z], axis=-1)


def batch_of_states(b: int):
    """B initial states on the standard case's momentum sphere, spread around m0."""
    rng = np.random.default_rng(0)
    m = M0 + 0.1 * rng.standard_normal((b, 3))
    m[0] = M0
    return m / np.linalg.norm(m, axis=1, keepdims=True) * np.linalg.norm(M0)


# ---------------------------------------------------------------------------------------


def single_trajectory(n: int, n_numpy: int, repeats: int, out: dict, lines: list):
    args = (jnp.asarray(M0), jnp.asarray(H), jnp.asarray(INERTIA))
    contenders = {
        "jaxsplit strang (axes)": (jaxsplit_run("strang", "axes", n), 4),
        "jaxsplit strang (casimir)": (jaxsplit_run("strang", "casimir", n), 2),
        "jaxsplit kahan-li-6 (casimir)": (jaxsplit_run("kahan-li-6", "casimir", n), 18),
        # kahan-li-6 (axes) through the library is not timed: with two-component rotations
        # it does not finish (see the fusion probe and the README)
        "matrix flows, strang (axes)": (variant_run("strang", "axes", "matrix", n), 4),
        "matrix flows, strang (casimir)": (variant_run("strang", "casimir", "matrix", n), 2),
        "matrix flows, kahan-li-6 (casimir)": (variant_run("kahan-li-6", "casimir", "matrix", n), 18),
        "scalar flows, strang (axes)": (variant_run("strang", "axes", "scalar", n), 4),
        "correction flows, strang (axes)": (variant_run("strang", "axes", "correction", n), 4),
        "correction flows, kahan-li-6 (casimir)": (variant_run("kahan-li-6", "casimir", "correction", n), 18),
        "scalar flows, strang (casimir)": (variant_run("strang", "casimir", "scalar", n), 2),
        "scalar flows + barriers, strang (casimir)": (variant_run("strang", "casimir", "scalar+barrier", n), 2),
        "scalar flows + barriers, kahan-li-6 (axes)": (
            variant_run("kahan-li-6", "axes", "scalar+barrier", n), 36),
        "scalar flows + barriers, kahan-li-6 (casimir)": (
            variant_run("kahan-li-6", "casimir", "scalar+barrier", n), 18),
        "hand-fused strang (axes)": (fused_strang_axes(n), 4),
        "hand-fused strang (casimir)": (fused_strang_casimir(n), 2),
    }
    # flows_per_step straight from the library, as a check on the counts above
    body = jaxsplit.RigidBody(INERTIA)
    for name, (_, rot) in contenders.items():
        if name.startswith("jaxsplit"):
            scheme, split = name.split()[1], name.split("(")[1].rstrip(")")
            assert jaxsplit.splitting(body, scheme, split).flows_per_step == rot, name

    compiled, compile_s, cases = {}, {}, {}
    for name, (fn, _) in contenders.items():
        compiled[name], compile_s[name] = aot(fn, *args)
        log(f"compiled {name} in {compile_s[name]:.2f} s")
        cases[name] = ready(compiled[name], *args)

    # same answer to round-off (hand-fused and jaxsplit do the same rotations in the same order)
    ref = np.asarray(compiled["jaxsplit strang (axes)"](*args))
    for name in ("hand-fused strang (axes)", "scalar flows, strang (axes)", "matrix flows, strang (axes)"):
        assert np.max(np.abs(np.asarray(compiled[name](*args)) - ref)) < 1e-9, name
    refc = np.asarray(compiled["jaxsplit strang (casimir)"](*args))
    for name in ("hand-fused strang (casimir)", "scalar flows, strang (casimir)",
                 "matrix flows, strang (casimir)", "scalar flows + barriers, strang (casimir)"):
        assert np.max(np.abs(np.asarray(compiled[name](*args)) - refc)) < 1e-9, name
    np_check = numpy_scalar_strang(n, M0, H, INERTIA)
    assert np.max(np.abs(np_check - ref)) < 1e-9, np.max(np.abs(np_check - ref))

    # NumPy Python loops are timed with fewer steps and scaled per step
    cases["numpy scalars, python loop, strang (axes)"] = lambda: numpy_scalar_strang(n_numpy, M0, H, INERTIA)
    cases["python floats + math, python loop, strang (axes)"] = lambda: numpy_scalar_strang(
        n_numpy, M0, H, INERTIA, cos=math.cos, sin=math.sin, scalar=float)
    rotations = {name: rot for name, (_, rot) in contenders.items()}
    rotations["numpy scalars, python loop, strang (axes)"] = 4
    rotations["python floats + math, python loop, strang (axes)"] = 4
    steps = {name: (n_numpy if "python loop" in name else n) for name in cases}

    log("timing single trajectories")
    times = interleaved(cases, repeats)
    per_step = {name: [t / steps[name] for t in ts] for name, ts in times.items()}
    base = "hand-fused strang (axes)"
    rows = []
    for name in cases:
        med = statistics.median(per_step[name])
        rows.append({
            "method": name,
            "steps_timed": steps[name],
            "median_call_s": statistics.median(times[name]),
            "ns_per_step": med * 1e9,
            "rotations_per_step": rotations[name],
            "ns_per_rotation": med * 1e9 / rotations[name],
            "ratio_vs_hand_fused_axes": paired_ratio(per_step, name, base),
            "compile_s": compile_s.get(name),
        })
    out["single"] = {"n_steps": n, "n_steps_python_loop": n_numpy, "repeats": repeats, "rows": rows}
    pairs = [
        ("jaxsplit strang (axes)", "hand-fused strang (axes)"),
        ("jaxsplit strang (casimir)", "hand-fused strang (casimir)"),
        ("matrix flows, strang (axes)", "hand-fused strang (axes)"),
        ("matrix flows, strang (casimir)", "hand-fused strang (casimir)"),
        ("scalar flows, strang (axes)", "hand-fused strang (axes)"),
        ("scalar flows + barriers, strang (casimir)", "hand-fused strang (casimir)"),
        ("matrix flows, kahan-li-6 (casimir)", "scalar flows + barriers, kahan-li-6 (casimir)"),
        ("jaxsplit kahan-li-6 (casimir)", "scalar flows + barriers, kahan-li-6 (casimir)"),
        ("jaxsplit strang (axes)", "jaxsplit strang (casimir)"),
        ("numpy scalars, python loop, strang (axes)", "jaxsplit strang (axes)"),
        ("python floats + math, python loop, strang (axes)", "jaxsplit strang (axes)"),
    ]
    out["single"]["ratios"] = {f"{a} / {b}": paired_ratio(per_step, a, b) for a, b in pairs}

    lines += [
        (f"### (a–c, e) Single trajectory, {n} steps (Python loops: {n_numpy} steps, scaled), "
        f"median of {repeats} interleaved rounds"),
        "",
        "| method | rotations/step | ns/step | ns/rotation | × hand-fused Strang (axes) | compile |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        comp = fmt(r["compile_s"]) if r["compile_s"] is not None else "—"
        lines.append(
            f"| {r['method']} | {r['rotations_per_step']} | {r['ns_per_step']:.4g} | "
            f"{r['ns_per_rotation']:.3g} | {r['ratio_vs_hand_fused_axes']:.3g} | {comp} |"
        )
    lines += ["", "Paired ratios (median over rounds of the per-round ratio):", ""]
    lines += [f"* {k}: **{v:.3g}×**" for k, v in out["single"]["ratios"].items()]
    lines.append("")


PROBE_VARIANTS = ("library", "matrix", "correction", "scalar", "scalar+barrier")


def fusion_probe(repeats: int, out: dict, lines: list):
    """One jitted step (no loop) of the library's composition against the same flows behind
    optimization barriers: shows the cost blow-up of long compositions as XLA fuses them."""
    args = (jnp.asarray(M0), jnp.asarray(H), jnp.asarray(INERTIA))
    # kahan-li-6 (axes) and kahan-li-8 (casimir) as is did not finish one step in 40 s
    probes = [("strang", "axes"), ("triple-jump-4", "casimir"), ("triple-jump-4", "axes"),
              ("blanes-moan-s6-prk", "casimir"), ("kahan-li-6", "casimir")]
    cases, info = {}, {}
    for scheme, split in probes:
        for variant in PROBE_VARIANTS:
            def one_step(m0, h, inertia, scheme=scheme, split=split, variant=variant):
                return step_variant(jaxsplit.RigidBody(inertia), scheme, split, variant, SHIFT)(m0, h)

            compiled, comp = aot(one_step, *args)
            hlo = compiled.as_text()
            name = f"{scheme} ({split}) {variant}"
            info[name] = {"compile_s": comp, "fusions": hlo.count(" fusion("),
                          "flows": len(jaxsplit.splitting(jaxsplit.RigidBody(INERTIA), scheme, split).word)}
            cases[name] = ready(compiled, *args)
            cases[name]()  # warm
            log(f"probe {name}: compiled in {comp:.2f} s")
    times = interleaved(cases, repeats)
    rows = []
    for scheme, split in probes:
        names = {v: f"{scheme} ({split}) {v}" for v in PROBE_VARIANTS}
        row = {"scheme": scheme, "split": split, "flows": info[names["library"]]["flows"]}
        for v, name in names.items():
            row[v] = {"time_s": statistics.median(times[name]), "fusions": info[name]["fusions"],
                      "compile_s": info[name]["compile_s"]}
        row["library / scalar+barrier"] = paired_ratio(times, names["library"], names["scalar+barrier"])
        rows.append(row)
    out["fusion_probe"] = rows
    lines += [
        "### Fusion probe: one jitted step (no loop), inertia traced",
        "",
        ("`library` = `jaxsplit.splitting` as the working tree has it; `matrix` = 3x3-matrix flows "
         "(HEAD); `correction` = m + e_i(...) + e_j(...) on scalars; `scalar` = two-component flows, "
         "stacked; `scalar+barrier` = the same, each behind `lax.optimization_barrier`."),
        "",
        "| scheme (split) | sub-flows | " + " | ".join(f"{v}: time (XLA fusions)" for v in PROBE_VARIANTS)
        + " | library / scalar+barrier |",
        "|---|---|" + "---|" * (len(PROBE_VARIANTS) + 1),
    ]
    for r in rows:
        cells = " | ".join(f"{fmt(r[v]['time_s'])} ({r[v]['fusions']})" for v in PROBE_VARIANTS)
        lines.append(f"| {r['scheme']} ({r['split']}) | {r['flows']} | {cells} | "
                     f"{r['library / scalar+barrier']:.3g}× |")
    lines += [
        "",
        ("Times include ~10–50 µs of call overhead. With two-component (scalar) rotations and no "
        "barrier, XLA fuses the whole step into one or two loop fusions whose elemental emitter "
        "recomputes earlier rotations for each output component, so the cost grows geometrically "
        "with the number of sub-flows; the matrix product (a dot) and the barriers both cut the chain."),
        "",
    ]


def dispatch_overhead(repeats: int, out: dict, lines: list):
    """Per-call cost of ``jaxsplit.integrate`` (Python-side partition + jit cache) at n = 1."""
    step = jaxsplit.splitting(jaxsplit.RigidBody(INERTIA), "strang", "casimir")
    m0, h = jnp.asarray(M0), jnp.asarray(H)
    compiled, _ = aot(lambda m0, h: jaxsplit.integrate(step, m0, h, 1).final, m0, h)
    jax.block_until_ready(jaxsplit.integrate(step, m0, h, 1).final)
    inner = 100

    def direct():
        for _ in range(inner):
            x = jaxsplit.integrate(step, m0, h, 1).final
        jax.block_until_ready(x)

    def precompiled():
        for _ in range(inner):
            x = compiled(m0, h)
        jax.block_until_ready(x)

    times = interleaved({"integrate().final": direct, "AOT-compiled": precompiled}, repeats)
    d, p = (statistics.median(times[k]) / inner for k in ("integrate().final", "AOT-compiled"))
    out["dispatch"] = {"integrate_call_s": d, "compiled_call_s": p}
    lines += [
        "### Per-call overhead (n = 1 step)",
        "",
        (f"`jaxsplit.integrate(step, m0, h, 1).final` costs {fmt(d)} per call against {fmt(p)} for the same "
        f"program called pre-compiled: {fmt(d - p)} of Python-side work per call (PyTree "
        "partition, hashing the static spec, jit cache lookup). It matters only for short runs."),
        "",
    ]


def batched(total: int, min_steps: int, repeats: int, out: dict, lines: list):
    rows = []
    for b in BATCHES:
        n = max(min_steps, total // b)
        m0s = jnp.asarray(batch_of_states(b))
        args = (m0s, jnp.asarray(H), jnp.asarray(INERTIA))

        def vm(run):
            return lambda ms, h, inertia: jax.vmap(run, in_axes=(0, None, None))(ms, h, inertia)

        contenders = {
            "jaxsplit strang (axes)": jaxsplit_run("strang", "axes", n),
            "jaxsplit strang (casimir)": jaxsplit_run("strang", "casimir", n),
            "hand-fused strang (axes)": fused_strang_axes(n),
            "matrix flows, strang (axes)": variant_run("strang", "axes", "matrix", n),
            "scalar flows + barriers, strang (axes)": variant_run("strang", "axes", "scalar+barrier", n),
        }
        cases, compile_s = {}, {}
        for name, fn in contenders.items():
            compiled, compile_s[name] = aot(vm(fn), *args)
            log(f"B={b}: compiled {name} in {compile_s[name]:.2f} s")
            cases[name] = ready(compiled, *args)
        n_np = max(min_steps // 10, min(n, (total // 8) // b))
        m0s_np = np.asarray(m0s)
        cases["numpy vectorised strang (axes)"] = lambda n_np=n_np, m0s_np=m0s_np: numpy_batch_strang(
            n_np, m0s_np, H, INERTIA)
        steps = {name: (n_np if name.startswith("numpy") else n) for name in cases}
        times = interleaved(cases, repeats)
        per = {name: [t / (steps[name] * b) for t in ts] for name, ts in times.items()}
        for name in cases:
            med = statistics.median(per[name])
            rows.append({
                "B": b, "method": name, "steps": steps[name],
                "state_steps_per_s": 1 / med,
                "ratio_vs_hand_fused_axes": paired_ratio(per, name, "hand-fused strang (axes)"),
                "compile_s": compile_s.get(name),
            })
    out["batched"] = {"total_state_steps": total, "repeats": repeats, "rows": rows}
    names = list(dict.fromkeys(r["method"] for r in rows))
    lines += [
        (f"### (d) Batched: `jax.vmap` over B initial states, ≈{total:.3g} state·steps per call, "
        f"median of {repeats} rounds"),
        "",
        "Million state·steps per second (× time of hand-fused Strang (axes) at the same B):",
        "",
        "| method | " + " | ".join(f"B = {b}" for b in BATCHES) + " |",
        "|---|" + "---|" * len(BATCHES),
    ]
    for name in names:
        cells = []
        for b in BATCHES:
            r = next(r for r in rows if r["B"] == b and r["method"] == name)
            cells.append(f"{r['state_steps_per_s'] / 1e6:.3g} ({r['ratio_vs_hand_fused_axes']:.2g}×)")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke mode: fewer steps and repeats")
    args = parser.parse_args(argv)
    quick = args.quick
    n, n_numpy, repeats = (20_000, 2_000, 3) if quick else (200_000, 20_000, 7)
    total, min_steps = (2**18, 20) if quick else (2**21, 100)

    t_start = time.perf_counter()
    command = "python benchmarks/throughput.py" + (" --quick" if quick else "")
    out = machine_info(command)
    out["case"] = {"inertia": INERTIA.tolist(), "m0": M0.tolist(), "h": H, "dtype": "float64"}
    lines = [
        f"## Throughput (`{command}`)",
        "",
        (f"{out['date_utc']}; {out['machine']}; load average at start "
        f"{', '.join(f'{v:.1f}' for v in out['load_average_at_start'])}; JAX {jax.__version__}, "
        f"NumPy {np.__version__}. Standard case, float64, h = {H}. jaxsplit at {out['git']}."),
        "",
    ]
    single_trajectory(n, n_numpy, repeats, out, lines)
    fusion_probe(repeats, out, lines)
    dispatch_overhead(repeats, out, lines)
    batched(total, min_steps, repeats, out, lines)
    out["wall_s"] = time.perf_counter() - t_start
    lines.append(f"Total wall time of the script: {out['wall_s']:.0f} s.")

    RESULTS.mkdir(exist_ok=True)
    stem = "throughput-quick" if quick else "throughput"
    (RESULTS / f"{stem}.json").write_text(json.dumps(out, indent=1))
    (RESULTS / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out


if __name__ == "__main__":
    sys.exit(main() and 0)
