"""Speed in the user's idiom: ``integrate`` called directly on a batch, inside the user's own
``jax.jit``, and as ``jax.jit(jax.vmap(...))`` over single states; compile time per scheme.

Cases (issue 30, acceptance 1 and 4): 256 free bodies (standard body, Casimir split,
h = 0.4, 250 steps) and 256 heavy tops (axes split, h = 0.05, 400 steps) with Strang,
Kahan–Li 8 and Sofroniou–Spaletta 10, each call form compiled fresh (``jax.clear_caches()``
before each: the first call's compile time is that form's own), then timed in interleaved
rounds. The host is shared: besides wall time the table gives the process's CPU time per
call (``time.process_time()``), which the other jobs' load does not inflate; the ratios are
of CPU times in the same round, and compile times are CPU seconds of the first call (which
the load moved 3× in wall time). ``--compile`` adds the first-call compile time of every
registered scheme (direct and ``jit(vmap)``, 256 free bodies, 10 steps), and
``--rolled`` the same runs with every word unrolled (``_compose.UNROLLED_UP_TO``) beside
the library's rolled patterns.

    python benchmarks/transformed.py [--rounds 7] [--compile] [--rolled]

Writes ``benchmarks/results/transformed.{md,json}``.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import jaxsplit  # noqa: E402
from jaxsplit.core import _compose  # noqa: E402

from _common import finish, header, log, machine_info  # noqa: E402

B = 256
SCHEMES = ("strang", "kahan-li-8", "sofroniou-spaletta-10")


def systems():
    rng = np.random.default_rng(0)
    m = rng.standard_normal((B, 3))
    g = rng.standard_normal((B, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    top = jaxsplit.heavy_top(jnp.array([2.0, 1.6, 1.0]), jnp.array([0.1, 0.05, 0.4]), 1.3)
    return {"free body": (lambda s: jaxsplit.splitting(body, s, "casimir"), jnp.asarray(m), 0.4, 250),
            "heavy top": (lambda s: jaxsplit.splitting(top, s), (jnp.asarray(m), jnp.asarray(g)), 0.05, 400)}


def forms(step, h, n):
    run = lambda x: jaxsplit.integrate(step, x, h, n).final
    return {"direct": run, "jit": jax.jit(run), "jit(vmap)": jax.jit(jax.vmap(run))}


def first_call(fn, x):
    """CPU seconds of the first call (tracing, compiling and one run): on this shared host the
    wall time of a compile moved 3× with the other jobs' load, its CPU time did not."""
    jax.clear_caches()
    start = time.process_time()
    jax.block_until_ready(fn(x))
    return time.process_time() - start


def timed(fn, x):
    jax.block_until_ready(fn(x))
    wall, cpu = time.perf_counter(), time.process_time()
    jax.block_until_ready(fn(x))
    return time.perf_counter() - wall, time.process_time() - cpu


def speed(rounds: int):
    rows = []
    for system, (make, x0, h, n) in systems().items():
        for scheme in SCHEMES:
            calls = forms(make(scheme), h, n)
            compile_s = {name: first_call(fn, x0) for name, fn in calls.items()}
            times = {name: [] for name in calls}
            for _ in range(rounds):
                for name, fn in calls.items():
                    times[name].append(timed(fn, x0))
            cpu = {name: np.array([c for _, c in t]) for name, t in times.items()}
            row = {"system": system, "scheme": scheme, "h": h, "steps": n, "compile_s": compile_s,
                   "wall_s": {k: min(w for w, _ in t) for k, t in times.items()},
                   "cpu_s": {k: float(np.min(v)) for k, v in cpu.items()},
                   "ratio": {k: float(np.median(v / cpu["direct"])) for k, v in cpu.items()}}
            rows.append(row)
            log(f"{system} {scheme}: " + ", ".join(f"{k} {row['cpu_s'][k] * 1e3:.1f} ms ({row['ratio'][k]:.2f}x, "
                                                   f"compile {compile_s[k]:.1f} s)" for k in calls))
    return rows


def compile_times(unrolled: bool):
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    x0 = jnp.asarray(np.random.default_rng(1).standard_normal((B, 3)))
    out = []
    for name in jaxsplit.schemes:
        scheme = jaxsplit.schemes[name]
        if scheme.order > 10 or not scheme.pieces_allowed(2):
            continue
        step = jaxsplit.splitting(body, name, "casimir")
        row = {"scheme": name, "order": scheme.order, "sub-flows": len(step.kernel_word)}
        for label, limit in (("rolled", _compose.UNROLLED_UP_TO),) + ((("unrolled", 10**9),) if unrolled else ()):
            saved, _compose.UNROLLED_UP_TO = _compose.UNROLLED_UP_TO, limit
            try:
                calls = forms(step, 0.4, 10)
                row[label] = {k: first_call(calls[k], x0) for k in ("direct", "jit(vmap)")}
            finally:
                _compose.UNROLLED_UP_TO = saved
        out.append(row)
        log(f"compile {name}: {row}")
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--compile", action="store_true")
    parser.add_argument("--rolled", action="store_true")
    args = parser.parse_args()
    start = time.perf_counter()
    command = "python benchmarks/transformed.py" + "".join(
        f" {flag}" for flag, on in (("--compile", args.compile), ("--rolled", args.rolled)) if on)
    out = machine_info(command)
    out["speed"] = speed(args.rounds)
    lines = header(out, "Speed in the user's idiom (`benchmarks/transformed.py`)") + [
        f"{B} states per batch; CPU time per call (min over {args.rounds} interleaved rounds), its ratio to the "
        "direct call (median of same-round ratios), wall time, and the first call's CPU seconds (compile included).", "",
        "| system | scheme | call | CPU ms | × direct | wall ms | compile s |", "|---|---|---|---|---|---|---|"]
    for row in out["speed"]:
        for k in row["cpu_s"]:
            lines.append(f"| {row['system']} | {row['scheme']} | `{k}` | {row['cpu_s'][k] * 1e3:.2f} | "
                         f"{row['ratio'][k]:.2f} | {row['wall_s'][k] * 1e3:.2f} | {row['compile_s'][k]:.2f} |")
    if args.compile:
        out["compile"] = compile_times(args.rolled)
        labels = ["rolled"] + (["unrolled"] if args.rolled else [])
        lines += ["", f"First-call CPU seconds (tracing, compiling, one run) of every registered scheme of order <= 10 on {B} free bodies "
                  "(Casimir split, 10 steps): direct / `jit(vmap)`" +
                  (f"; words longer than {_compose.UNROLLED_UP_TO} sub-flows rolled (the library) and unrolled"
                   if args.rolled else "") + ".", "",
                  "| scheme | order | sub-flows a step | " + " | ".join(labels) + " |",
                  "|---|---|---|" + "---|" * len(labels)]
        for row in out["compile"]:
            lines.append(f"| {row['scheme']} | {row['order']} | {row['sub-flows']} | " + " | ".join(
                f"{row[k]['direct']:.2f} / {row[k]['jit(vmap)']:.2f}" for k in labels) + " |")
    finish("transformed", out, lines, start)


if __name__ == "__main__":
    main()
