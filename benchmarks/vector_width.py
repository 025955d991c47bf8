"""What 512-bit vectors buy: jaxsplit's per-program compiler option against XLA's 256-bit default.

XLA's CPU code generator asks LLVM for 256-bit vectors; ``jaxsplit.compiler_options()`` asks
for 512 (``xla_cpu_prefer_vector_width``), and jaxsplit's own programs (``integrate``, sweeps,
order fits) are compiled with it. The option is per program, so both variants of every case
run in one process, compiled side by side, their calls interleaved round by round (load from
other jobs hits both alike). Per case: run time of each (median over rounds), the paired
speed-up (median of per-round ratios), compile time of each, and whether the results are
bit-identical. diffrax's Dopri8 on the same bodies shows what the option does for a peer.

    python benchmarks/vector_width.py [--rounds 7]

Writes ``benchmarks/results/vector_width.{md,json}``.
"""

import argparse
import statistics
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from _common import finish, fmt, header, interleaved, log, machine_info, paired_ratio

import jaxsplit

jax.config.update("jax_enable_x64", True)
WIDE = {"xla_cpu_prefer_vector_width": 512}


def states(b, seed=0):
    m = np.random.default_rng(seed).standard_normal((b, 3))
    return jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True))


def cases():
    """{name: (function, arguments)}: each compiled twice, the run's kernel chosen as integrate does."""
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    out = {}
    for b, scheme, n in ((1, "kahan-li-8", 20_000), (16, "mclachlan-ss15", 4000), (256, "mclachlan-ss15", 1000),
                         (256, "kahan-li-8", 1000), (4096, "mclachlan-ss15", 50), (10**4, "strang", 500),
                         (10**5, "strang", 50)):
        x = states(b) if b > 1 else jnp.asarray(jaxsplit.STANDARD_CASE.m0)
        step = jaxsplit.splitting(body, scheme, "casimir")
        label = "one body" if b == 1 else f"{b:,} bodies"
        out[f"{label}, {jaxsplit.schemes[scheme].name}, {n:,} steps"] = (
            lambda y, step=step, n=n: step.advance(y, 0.4, n), (x,))
    top = jaxsplit.heavy_top(jnp.array([1.0, 1.0, 0.5]), jnp.array([0.0, 0.0, 0.3]), 1.5)
    for b, n in ((1, 20_000), (1000, 200)):
        x = (states(b, 1) if b > 1 else jnp.array([0.3, -0.2, 1.1]), jnp.broadcast_to(jnp.array([0.1, 0.2, 0.97]), (b, 3)) if b > 1
             else jnp.array([0.1, 0.2, 0.97]))
        step = jaxsplit.splitting(top, "strang")
        loss = lambda y, step=step, n=n: jnp.sum(jaxsplit.integrate(step, y, 0.01, n, adjoint="reversible").final[0])
        label = "one heavy top" if b == 1 else f"{b:,} heavy tops"
        out[f"{label}, Strang, {n:,} steps"] = (lambda y, step=step, n=n: step.advance(y, 0.01, n), (x,))
        out[f"{label}, reversible gradient, {n:,} steps"] = (jax.grad(loss), (x,))
    term = diffrax.ODETerm(lambda t, m, args: body.vector_field(m))
    out["256 bodies, diffrax Dopri8 fixed, 1,000 steps (peer)"] = (
        lambda y: diffrax.diffeqsolve(term, diffrax.Dopri8(), 0.0, 400.0, 0.4, y, max_steps=1001).ys[-1], (states(256),))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    rounds = parser.parse_args().rounds
    out = machine_info("python benchmarks/vector_width.py")
    start = time.perf_counter()
    out["cases"] = {}
    lines = header(out, "512-bit vectors for jaxsplit's programs (`benchmarks/vector_width.py`)") + [
        (f"Both variants compiled in one process, calls interleaved over {rounds} rounds; run = median over rounds, "
         "speed-up = median of the per-round ratios (256-bit / 512-bit); compile = first call (compilation and one "
         "run); identical: the two results bit for bit."), "",
        "| case | run, 256-bit (XLA default) | run, 512-bit | speed-up | compile 256 / 512 | identical |",
        "|---|---|---|---|---|---|"]
    for name, (fn, args) in cases().items():
        variants = {"256": jax.jit(fn), "512": jax.jit(fn, compiler_options=WIDE)}
        results, compile_s = {}, {}
        for key, f in variants.items():
            t0 = time.perf_counter()
            results[key] = jax.block_until_ready(f(*args))
            compile_s[key] = time.perf_counter() - t0
        times = interleaved({key: (lambda f=f, args=args: jax.block_until_ready(f(*args))) for key, f in variants.items()}, rounds)
        same = all(np.array_equal(np.asarray(a), np.asarray(b)) for a, b in
                   zip(jax.tree_util.tree_leaves(results["256"]), jax.tree_util.tree_leaves(results["512"])))
        entry = {"run_s": {k: statistics.median(v) for k, v in times.items()}, "compile_s": compile_s,
                 "speed_up": paired_ratio(times, "256", "512"), "identical": same}
        out["cases"][name] = entry
        lines.append(f"| {name} | {fmt(entry['run_s']['256'])} | {fmt(entry['run_s']['512'])} | "
                     f"{entry['speed_up']:.2f}× | {compile_s['256']:.2f} / {compile_s['512']:.2f} s | {'yes' if same else 'no'} |")
        log(lines[-1])
    finish("vector_width", out, lines, start)


if __name__ == "__main__":
    main()
