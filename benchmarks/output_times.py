"""What does output at given times (``integrate(..., ts=)``) cost against a run of the same
steps? 256 free bodies (the select layout), Kahan–Li 8 on the Casimir split, h = 0.05, to
T = 25 (500 steps): the plain run of n steps, the run with 7 output times (a loop with a
traced count per output: grid steps, then a partial step), and the reversible gradient of
each (with respect to the inertia, traced, so XLA's cos and sin), compiled ahead of time and
timed in interleaved rounds. The ratio ts= / n steps should be near 1: each output adds one
partial step.

    python benchmarks/output_times.py [--rounds 7]

Writes ``benchmarks/results/output_times.{md,json}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, interleaved, log, machine_info, ready

import jaxsplit

H, T, OUTPUTS = 0.05, 25.0, 7


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    out = machine_info("python benchmarks/output_times.py")
    start = time.perf_counter()
    m = np.random.default_rng(0).standard_normal((256, 3))
    m0 = jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True))
    inertia = jnp.asarray(jaxsplit.STANDARD_CASE.inertia)
    times = jnp.linspace(T / OUTPUTS, T, OUTPUTS)
    n = round(T / H)

    def step(i):
        return jaxsplit.splitting(jaxsplit.RigidBody(i, allow_nonphysical=True), "kahan-li-8", "casimir", shift=1)

    def n_steps(i, x, adjoint="store"):
        return jaxsplit.integrate(step(i), x, H, n, adjoint=adjoint).final

    def at_times(i, x, adjoint="store"):
        return jaxsplit.integrate(step(i), x, H, ts=times, adjoint=adjoint).x

    cases = {
        "run, n steps": n_steps,
        "run, ts=": at_times,
        "reversible gradient, n steps": jax.grad(lambda i, x: jnp.sum(n_steps(i, x, "reversible") ** 3)),
        "reversible gradient, ts=": jax.grad(lambda i, x: jnp.sum(at_times(i, x, "reversible") ** 3)),
    }
    compiled = {name: jax.jit(f).lower(inertia, m0).compile() for name, f in cases.items()}
    timed = interleaved({name: ready(p, inertia, m0) for name, p in compiled.items()}, args.rounds)
    rows = {name: statistics.median(t) for name, t in timed.items()}
    for name, t in rows.items():
        log(f"{name}: {t * 1e3:.2f} ms")
    out["rows"] = rows
    lines = header(out, "Output at given times against a run of the same steps (`benchmarks/output_times.py`)") + [
        (f"256 free bodies, Kahan–Li 8, Casimir split, h = {H}, T = {T:g} ({n} steps; {OUTPUTS} output times); "
         f"median over {args.rounds} interleaved rounds; the inertia and the states are arguments of the "
         "compiled function (the inertia traced: XLA's cos and sin)."), "",
        "| | n steps | ts= | ts= / n steps |", "|---|---|---|---|"]
    for kind in ("run", "reversible gradient"):
        a, b = rows[f"{kind}, n steps"], rows[f"{kind}, ts="]
        lines.append(f"| {kind} | {a * 1e3:.3g} ms | {b * 1e3:.3g} ms | **{b / a:.2f}×** |")
    finish("output_times", out, lines, start)


if __name__ == "__main__":
    main()
