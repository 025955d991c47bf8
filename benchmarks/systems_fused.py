"""Every shipped system against a hand-fused JAX loop of the same algebra (issue 30, item 3).

For each spinning-body system the library ships — the free body (Casimir split), the heavy
top (axes split), the Lagrange top (symmetric split), the attitude (m, Q) and (m, q) (axes
split) and the gravity-gradient satellite (axes split) — and for Strang and Kahan–Li 8, on a
batch of 256 states and on one state, float64:

* jaxsplit, the direct call ``integrate(step, x, h, n).final`` (the batch as leading axis; one
  state unbatched);
* jaxsplit in the user's idiom ``jax.jit(jax.vmap(lambda x: integrate(step, x, h, n).final))``
  (one state as a batch of 1);
* a hand-fused JAX loop written here: one ``lax.scan`` over the steps, jitted, whose body
  applies the same sub-flows in the same order (the composition's merged word, the first
  sub-flow merged across steps, ``Composition._sequences``: the word is the scheme's data,
  taken from the composer; every flow is written out below) with the rotations inline —
  two components per rotation about a coordinate axis, Rodrigues about m for the Lagrange
  top's spin, the quaternion product written out, the kick written directly. Parameters are
  Python constants (what a hand-written loop bakes in), h is an argument.

The hand-fused loop is tuned (``fused_run``): the word's repeating pattern as an inner scan
(inlined whole it compiled for up to a minute and ran 2–15× slower); the state carried as a
tuple of component arrays (B,) ("components", batch last), or stacked into one array after
every sub-flow, components first (P, B) or batch first (B, P); the step scan unrolled 1 or 2
steps; the library's polynomial cos/sin (``so3.half_turn``, increments from the half angle) or
XLA's ``jnp.cos``/``jnp.sin``. Every variant runs in the same interleaved rounds and the
comparison is against the fastest (least median CPU time) per case, named in the table: this
favours the hand-fused loop (the least of several noisy medians). Every
variant's final state is checked against jaxsplit's direct call (max |difference| <= 1e-11,
printed): it is the same algorithm, so only rounding differs.

Times are CPU seconds of the process (``time.process_time()``) around each call that waits
for its result, and wall seconds, in interleaved rounds (``_common.interleaved``); a time is
the median over the rounds, a ratio the median of the per-round ratios (CPU time). The host
is shared with other jobs: CPU time is what their load inflates least.

``--profile`` (implied for any case beyond 2×) counts the kernels of the compiled programs
(fusions, sine/cosine, transposes, selects, scatters, while loops, calls) for the record.

    python benchmarks/systems_fused.py [--quick] [--rounds 5]

Writes ``benchmarks/results/systems_fused.{md,json}`` (``-quick`` with ``--quick``).
"""

import argparse
import re
import statistics
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import finish, header, interleaved, log, machine_info, paired_ratio  # noqa: E402

import jaxsplit  # noqa: E402
from jaxsplit.core._compose import _period  # noqa: E402
from jaxsplit.systems import so3  # noqa: E402

warnings.filterwarnings("ignore", category=FutureWarning)  # the standard test body is non-physical

SCHEMES = ("strang", "kahan-li-8")
BATCHES = (256, 1)
TOLERANCE = 1e-11
INERTIA = (2.0, 1.6, 1.0)  # a physical asymmetric body for the tops, the attitude and the satellite
CHI, WEIGHT = (0.1, 0.05, 0.4), 1.3  # the heavy top of ``transformed.py``
LAGRANGE = ((1.0, 1.0, 0.5), (0.0, 0.0, 0.4), 1.0)  # I_1 = I_2, χ on axis 3
RATE = 0.8  # gravity-gradient orbital rate Ω


# ---------------------------------------------------------------------------- trigonometry
# A rotation of the pair (a, b) by φ: (a cos φ − b sin φ, b cos φ + a sin φ). Two forms.

def pair_poly(phi):
    """From the library's kernel at φ/2 (one straight-line polynomial), as an increment:
    a − 2s(s a + c b), b + 2s(c a − s b), (c, s) = ±(cos φ/2, sin φ/2)."""
    c, s = so3.half_turn(phi / 2)
    u = s + s
    return lambda a, b: (a - u * (s * a + c * b), b + u * (c * a - s * b))


def pair_xla(phi):
    c, s = jnp.cos(phi), jnp.sin(phi)
    return lambda a, b: (c * a - s * b, c * b + s * a)


TRIG = {"poly": pair_poly, "xla": pair_xla}


def turn_axis(vectors, k, theta, pair):
    """R_k(θ) = exp(−θ hat(e_k)) on each 3-vector (a list of components) of ``vectors``: the
    pair (v_i, v_j), i = k+1, j = k+2, turned by −θ, one cos/sin for all."""
    i, j = (k + 1) % 3, (k + 2) % 3
    turn = pair(-theta)
    out = []
    for v in vectors:
        v = list(v)
        v[i], v[j] = turn(v[i], v[j])
        out.append(v)
    return out


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def rodrigues(v, a, trig):
    """exp(−hat(a)) v: v turned about a by −|a| (a ≠ 0 here: the states have m ≠ 0)."""
    sq = a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
    norm = jnp.sqrt(sq)
    av = cross(a, v)
    aav = cross(a, av)
    if trig == "poly":  # v − σ(cos(|a|/2) a×v − ½σ a×(a×v)), σ = sin(|a|/2)/(|a|/2)
        c, s = so3.half_turn(norm / 2)
        sigma = s / (norm / 2)
        return [v[k] - sigma * (c * av[k] - 0.5 * sigma * aav[k]) for k in range(3)]
    sin_n, one_minus_cos = jnp.sin(norm) / norm, (1 - jnp.cos(norm)) / sq
    return [v[k] - sin_n * av[k] + one_minus_cos * aav[k] for k in range(3)]


def quaternion_turn(q, k, theta, pair):
    """q ← q ⊗ (cos θ/2, sin θ/2 e_k): the pairs (w, q_k) and (q_i, q_j) turned by θ/2
    (w' = C w − S q_k, q_k' = C q_k + S w, q_i' = C q_i + S q_j, q_j' = C q_j − S q_i)."""
    i, j = (k + 1) % 3, (k + 2) % 3
    turn = pair(theta / 2)
    w, v = q[0], list(q[1:])
    w, v[k] = turn(w, v[k])
    v[j], v[i] = turn(v[j], v[i])
    return [w] + v


# ---------------------------------------------------------------------------- the systems' flows, written out
# A component state: a tuple of parts, each a list of component arrays (the attitude Q a list
# of three rows). Each system gives flows(trig) -> [flow(state, t)] in the split's piece order.

def free_body_flows(trig):
    w = 1 / np.asarray(jaxsplit.STANDARD_CASE.inertia)
    k = 1  # the Casimir split's shift for the standard body (the middle 1/I)
    rates = {a: float(w[a] - w[k]) for a in (0, 2)}

    def rotation(a):
        def flow(state, t):
            (m,) = state
            return tuple(turn_axis([m], a, m[a] * (rates[a] * t), TRIG[trig]))
        return flow

    return [rotation(0), rotation(2)]


def axes_rotation(a, rate, trig, kind):
    """R_a(θ), θ = rate m_a t, on m and the other part ("vector": Γ; "rows": Q's rows; "quaternion")."""
    def flow(state, t):
        m, other = state
        theta = m[a] * (rate * t)
        pair = TRIG[trig](-theta) if kind != "quaternion" else None
        if kind == "vector":
            m, other = turn_axis([m, other], a, theta, lambda _: pair)
        elif kind == "rows":
            m, *rows = turn_axis([m, *other], a, theta, lambda _: pair)
            other = rows
        else:
            (m,) = turn_axis([m], a, theta, TRIG[trig])
            other = quaternion_turn(other, a, theta, TRIG[trig])
        return (m, other)
    return flow


def potential_flows(trig, inertia, torque):
    """Three rotations of (m, Γ) and the kick m ← m + t Γ × ∇V(Γ)."""
    w = 1 / np.asarray(inertia)

    def kick(state, t):
        m, g = state
        f = torque(g)
        tau = cross(g, f)
        return ([m[k] + t * tau[k] for k in range(3)], g)

    return [axes_rotation(a, float(w[a]), trig, "vector") for a in range(3)] + [kick]


def heavy_top_flows(trig):
    chi = [WEIGHT * c for c in CHI]
    return potential_flows(trig, INERTIA, lambda g: chi)


def gravity_gradient_flows(trig):
    scale = [3 * RATE**2 * i for i in INERTIA]
    return potential_flows(trig, INERTIA, lambda g: [scale[k] * g[k] for k in range(3)])


def lagrange_flows(trig):
    inertia, chi, weight = LAGRANGE
    w = 1 / np.asarray(inertia)
    chi = [weight * c for c in chi]
    rotation = axes_rotation(2, float(w[2] - w[0]), trig, "vector")

    def kinetic(state, t):  # the rotation about axis 3, then Γ spun about m (m fixed)
        m, g = rotation(state, t)
        c = float(w[0]) * t
        return (m, rodrigues(g, [c * m[k] for k in range(3)], trig))

    def kick(state, t):
        m, g = state
        tau = cross(g, chi)
        return ([m[k] + t * tau[k] for k in range(3)], g)

    return [kinetic, kick]


def attitude_flows(kind):
    def flows(trig):
        w = 1 / np.asarray(INERTIA)
        return [axes_rotation(a, float(w[a]), trig, kind) for a in range(3)]
    return flows


# ---------------------------------------------------------------------------- states and layouts

def random_states(b, parts, seed=0):
    """B random states: m normal (|m| ~ 1.7), Γ a unit vector, Q a rotation, q a unit quaternion."""
    rng = np.random.default_rng(seed)
    m = rng.standard_normal((b, 3))
    if parts == "m":
        return jnp.asarray(m)
    q = rng.standard_normal((b, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    if parts == "vector":
        return jnp.asarray(m), jnp.asarray(q[:, 1:] / np.linalg.norm(q[:, 1:], axis=1, keepdims=True))
    if parts == "quaternion":
        return jnp.asarray(m), jnp.asarray(q)
    return jnp.asarray(m), so3.quaternion_to_matrix(jnp.asarray(q))


def to_components(x, parts):
    """The state (leading batch axis) as component arrays: (m,), (m, Γ), (m, Q rows), (m, q)."""
    if parts == "m":
        return ([x[..., k] for k in range(3)],)
    m, a = x
    m = [m[..., k] for k in range(3)]
    if parts == "attitude":
        return (m, [[a[..., r, k] for k in range(3)] for r in range(3)])
    return (m, [a[..., k] for k in range(a.shape[-1])])


def from_components(c, parts):
    if parts == "m":
        return jnp.stack(c[0], axis=-1)
    m, a = c
    m = jnp.stack(m, axis=-1)
    if parts == "attitude":
        return m, jnp.stack([jnp.stack(row, axis=-1) for row in a], axis=-2)
    return m, jnp.stack(a, axis=-1)


def fused_run(flows, sequences, parts, n, layout, unroll):
    """The hand-fused loop: head, ``n`` times the body, tail (``Composition._sequences``: the
    merged word with the first sub-flow carried across steps), one jitted ``lax.scan`` over the
    steps. Inside a step the word's repeating pattern of pieces (a Strang stage's) runs as an
    inner ``lax.scan`` over its rows of weights, each row's sub-flows written out (the word
    unrolled inline compiled for 8.4 s (free body) to 64 s (heavy top) for Kahan–Li 8 and ran
    2–15× slower: XLA fused the word's chain and recomputed it per output; an
    ``optimization_barrier`` per sub-flow did not change that). Layouts: "components", a tuple
    of (B,) arrays; "stacked (P, B)" / "stacked (B, P)", all components in one array, stacked
    back after every sub-flow."""
    head, body, tail = sequences
    pieces = tuple(p for p, _ in body)
    period = _period(pieces)
    reps = len(body) // period if len(body) > period else 0
    weights = np.array([w for _, w in body[:reps * period]]).reshape(reps, period)
    rest = body[reps * period:]

    def run(x, h):
        c = to_components(x, parts)
        if layout == "components":
            fl, pack, unpack = flows, (lambda c: c), (lambda c: c)
        else:
            axis = 0 if layout == "stacked (P, B)" else -1
            tree = jax.tree_util.tree_structure(c)
            pack = lambda c: jnp.stack(jax.tree_util.tree_leaves(c), axis=axis)  # noqa: E731
            unpack = lambda a: jax.tree_util.tree_unflatten(  # noqa: E731
                tree, [a[k] if axis == 0 else a[..., k] for k in range(tree.num_leaves)])
            fl = [lambda a, t, f=f: pack(f(unpack(a), t)) for f in flows]

        def apply(a, word):
            for piece, weight in word:
                a = fl[piece](a, weight * h)
            return a

        def inner(a, row):
            for q in range(period):
                a = fl[pieces[q]](a, row[q] * h)
            return a, None

        def one_step(a, _):
            if reps:
                a = jax.lax.scan(inner, a, jnp.asarray(weights))[0]
            return apply(a, rest), None

        a = apply(pack(c), head)
        a = jax.lax.scan(one_step, a, length=n, unroll=unroll)[0]
        return from_components(unpack(apply(a, tail)), parts)

    return jax.jit(run)


# ---------------------------------------------------------------------------- the cases

def systems():
    std = jnp.asarray(jaxsplit.STANDARD_CASE.inertia)
    inertia = jnp.asarray(INERTIA)
    return {
        "free body (Casimir split)": (jaxsplit.RigidBody(std, allow_nonphysical=True), "casimir", "m", free_body_flows, 0.01),
        "heavy top (axes split)": (jaxsplit.heavy_top(inertia, jnp.asarray(CHI), WEIGHT), "axes", "vector",
                                   heavy_top_flows, 0.002),
        "Lagrange top (symmetric split)": (jaxsplit.heavy_top(*(jnp.asarray(v) for v in LAGRANGE)), "symmetric",
                                           "vector", lagrange_flows, 0.002),
        "attitude (m, Q) (axes split)": (jaxsplit.attitude(inertia), "axes", "attitude", attitude_flows("rows"),
                                         0.01),
        "attitude (m, q) (axes split)": (jaxsplit.attitude(inertia, quaternion=True), "axes", "quaternion",
                                         attitude_flows("quaternion"), 0.01),
        "gravity gradient (axes split)": (jaxsplit.gravity_gradient(inertia, RATE), "axes", "vector",
                                          gravity_gradient_flows, 0.002),
    }


VARIANTS = (("components", 1, "poly"), ("components", 2, "poly"), ("components", 1, "xla"),
            ("stacked (P, B)", 1, "poly"), ("stacked (P, B)", 1, "xla"), ("stacked (B, P)", 1, "xla"))


def variants(parts):
    """Every variant but the stacked polynomial ones on states of parts: a heavy top's
    (P, B) with the polynomial compiled for 45 s and ran 41 s per call (Kahan–Li 8, 256 tops,
    400 steps; 0.37 s with XLA's cos/sin): XLA fused the polynomial into every stacked output."""
    return tuple(v for v in VARIANTS if parts == "m" or not (v[0].startswith("stacked") and v[2] == "poly"))


def variant_name(v):
    layout, unroll, trig = v
    return f"hand-fused, {layout}, unroll {unroll}, {'polynomial' if trig == 'poly' else 'XLA cos/sin'}"


def max_diff(a, b):
    return max(float(jnp.max(jnp.abs(u - v))) for u, v in zip(jax.tree_util.tree_leaves(a),
                                                              jax.tree_util.tree_leaves(b)))


def timed(fn, cpu_log):
    """``fn`` waiting for its result, its CPU seconds appended to ``cpu_log`` (the wall seconds
    are ``interleaved``'s)."""
    def call():
        t = time.process_time()
        jax.block_until_ready(fn())
        cpu_log.append(time.process_time() - t)
    return call


KERNEL_PATTERNS = {"fusions": r"^\s*(ROOT )?\S+ = \S+ fusion\(", "sine": r" sine\(", "cosine": r" cosine\(",
                   "transpose": r" transpose\(", "select": r" select\(", "scatter": r" scatter\(",
                   "while": r" while\(", "calls": r" call\(", "copies": r" copy\(",
                   "one-kernel calls": r"xla_cpu_small_call"}


def hlo_counts(compiled_text):
    return {k: len(re.findall(p, compiled_text, flags=re.M)) for k, p in KERNEL_PATTERNS.items()}


def profile(fn, *args):
    return hlo_counts(jax.jit(fn).lower(*args).compile().as_text())


def run_case(name, system, split, parts, make_flows, h, scheme, b, n, rounds, want_profile):
    step = jaxsplit.splitting(system, scheme, split)
    sequences = step._sequences()
    x = random_states(b, parts)
    single = jax.tree_util.tree_map(lambda a: a[0], x)
    direct_x = single if b == 1 else x
    run = lambda s: jaxsplit.integrate(step, s, h, n).final  # noqa: E731
    mapped = jax.jit(jax.vmap(run))
    reference = jax.block_until_ready(run(direct_x))
    ref_batched = jax.tree_util.tree_map(lambda a: a[None], reference) if b == 1 else reference
    fns = {"jaxsplit, direct": lambda: run(direct_x), "jaxsplit, jit(vmap)": lambda: mapped(x)}
    diffs = {"jaxsplit, jit(vmap)": max_diff(mapped(x), ref_batched)}
    compile_s = {}
    for v in variants(parts):
        fused = fused_run(make_flows(v[2]), sequences, parts, n, v[0], v[1])
        t = time.process_time()
        out = jax.block_until_ready(fused(x, h))
        compile_s[variant_name(v)] = time.process_time() - t
        diffs[variant_name(v)] = max_diff(out, ref_batched)
        fns[variant_name(v)] = lambda f=fused: f(x, h)
    for k, d in diffs.items():
        if not d <= TOLERANCE:
            raise AssertionError(f"{name} {scheme} B={b}: {k} differs from jaxsplit by {d:.2e}")
    for fn in fns.values():  # warm
        jax.block_until_ready(fn())
    cpu = {k: [] for k in fns}
    wall = interleaved({k: timed(fn, cpu[k]) for k, fn in fns.items()}, rounds)
    fused_names = [variant_name(v) for v in variants(parts)]
    best = min(fused_names, key=lambda k: statistics.median(cpu[k]))
    row = {"system": name, "scheme": scheme, "B": b, "steps": n, "h": h, "sub_flows_per_step": len(sequences[1]),
           "cpu_s": {k: statistics.median(v) for k, v in cpu.items()},
           "wall_s": {k: statistics.median(v) for k, v in wall.items()},
           "cpu_rounds": cpu, "wall_rounds": wall, "max_abs_diff_vs_direct": diffs, "fused_first_call_cpu_s": compile_s,
           "best_fused": best,
           "ratio_cpu": {k: paired_ratio(cpu, k, best) for k in ("jaxsplit, direct", "jaxsplit, jit(vmap)")},
           "ratio_wall": {k: paired_ratio(wall, k, best) for k in ("jaxsplit, direct", "jaxsplit, jit(vmap)")}}
    slow = max(row["ratio_cpu"].values()) > 2
    if want_profile or slow:
        best_v = variants(parts)[fused_names.index(best)]
        row["hlo"] = {"jaxsplit, direct": profile(run, direct_x), "jaxsplit, jit(vmap)": profile(jax.vmap(run), x),
                      best: profile(fused_run(make_flows(best_v[2]), sequences, parts, n, best_v[0], best_v[1]),
                                    x, h)}
    log(f"{name} {scheme} B={b}: direct {row['cpu_s']['jaxsplit, direct'] * 1e3:.2f} ms, jit(vmap) "
        f"{row['cpu_s']['jaxsplit, jit(vmap)'] * 1e3:.2f} ms, best fused {row['cpu_s'][best] * 1e3:.2f} ms ({best}); "
        f"ratios {row['ratio_cpu']['jaxsplit, direct']:.2f} / {row['ratio_cpu']['jaxsplit, jit(vmap)']:.2f}; "
        f"max diff {max(diffs.values()):.1e}")
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--rounds", type=int, default=None)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--only", default=None, help="run only the systems whose name contains this")
    args = parser.parse_args()
    rounds = args.rounds or (3 if args.quick else 5)
    steps = {"strang": 400, "kahan-li-8": 100} if args.quick else {"strang": 2000, "kahan-li-8": 500}
    start = time.perf_counter()
    command = "python benchmarks/systems_fused.py" + "".join(
        f" {f}" for f, on in (("--quick", args.quick), ("--profile", args.profile)) if on) + (
        f" --rounds {args.rounds}" if args.rounds else "") + (f" --only '{args.only}'" if args.only else "")
    out = machine_info(command)
    out["rows"] = rows = []
    for name, (system, split, parts, make_flows, h) in systems().items():
        if args.only and args.only not in name:
            continue
        for scheme in SCHEMES:
            for b in BATCHES:
                rows.append(run_case(name, system, split, parts, make_flows, h, scheme, b, steps[scheme], rounds,
                                     args.profile))
    lines = header(out, "Every shipped system against a hand-fused loop (`benchmarks/systems_fused.py`, issue 30 item 3)")
    lines += [f"float64; {steps['strang']} Strang steps, {steps['kahan-li-8']} Kahan–Li 8 steps; B = 256 states "
              f"(direct: the (256, …) batch) and B = 1 (direct: one unbatched state; `jit(vmap)`: a batch of 1). "
              f"CPU time per call, median of {rounds} interleaved rounds; × = median of the per-round ratios of CPU "
              "times to the fastest hand-fused variant of the case (wall-time ratio in brackets). Within 2×: both "
              "idioms' CPU ratios ≤ 2.", "",
              "| system | scheme | B | sub-flows/step | jaxsplit direct | jaxsplit `jit(vmap)` | hand-fused (best) | "
              "× direct | × `jit(vmap)` | within 2× | best hand-fused variant | max \\|Δ\\| |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        best = r["best_fused"]
        ok = max(r["ratio_cpu"].values()) <= 2
        lines.append(
            f"| {r['system']} | {r['scheme']} | {r['B']} | {r['sub_flows_per_step']} | "
            f"{r['cpu_s']['jaxsplit, direct'] * 1e3:.3g} ms | {r['cpu_s']['jaxsplit, jit(vmap)'] * 1e3:.3g} ms | "
            f"{r['cpu_s'][best] * 1e3:.3g} ms | {r['ratio_cpu']['jaxsplit, direct']:.2f} "
            f"({r['ratio_wall']['jaxsplit, direct']:.2f}) | {r['ratio_cpu']['jaxsplit, jit(vmap)']:.2f} "
            f"({r['ratio_wall']['jaxsplit, jit(vmap)']:.2f}) | {'yes' if ok else '**no**'} | "
            f"{best.removeprefix('hand-fused, ')} | {max(r['max_abs_diff_vs_direct'].values()):.1e} |")
    lines += ["", "Every hand-fused variant per case, CPU ms (median):", "",
              "| system | scheme | B | " + " | ".join(variant_name(v).removeprefix("hand-fused, ") for v in VARIANTS)
              + " |", "|---|---|---|" + "---|" * len(VARIANTS)]
    for r in rows:
        lines.append(f"| {r['system']} | {r['scheme']} | {r['B']} | " + " | ".join(
            f"{r['cpu_s'][variant_name(v)] * 1e3:.3g}" if variant_name(v) in r["cpu_s"] else "—" for v in VARIANTS)
            + " |")
    profiled = [r for r in rows if "hlo" in r]
    if profiled:
        lines += ["", "Compiled programs (counts in the optimized HLO text: fusion kernels, sine, cosine, transposes, "
                  "selects, scatters, while loops, calls, copies, loops tagged to compile as one kernel):", "",
                  "| system | scheme | B | program | " + " | ".join(KERNEL_PATTERNS) + " |",
                  "|---|---|---|---|" + "---|" * len(KERNEL_PATTERNS)]
        for r in profiled:
            for prog, counts in r["hlo"].items():
                lines.append(f"| {r['system']} | {r['scheme']} | {r['B']} | {prog} | " + " | ".join(
                    str(counts[k]) for k in KERNEL_PATTERNS) + " |")
    finish("systems_fused", out, lines, start, quick=args.quick)


if __name__ == "__main__":
    main()
