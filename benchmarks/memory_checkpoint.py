"""Peak memory of reverse-mode gradients through n steps, with and without checkpointing.

The loss is the squared distance of m(n h) from a target, differentiated with respect to
the inertia, for the Strang splitting of the standard body at h = 0.01, batched over
``--batch`` initial states (vmap) so the numbers are well above XLA's fixed overhead.
Memory is XLA's own account of the compiled gradient program: ``memory_analysis()`` of
``jit(grad(loss))`` — temporary buffers (the peak working set XLA allocates for the run:
the scan's saved residuals dominate) plus arguments and outputs. Checkpointed runs use
``jaxsplit.integrate_checkpointed`` with blocks of B = ⌈√n⌉ steps, so the expectation is
O(n) without and O(√n) with checkpointing.

    python benchmarks/memory_checkpoint.py [--counts 1000 10000 100000 1000000] [--batch 16]
"""

import argparse
import json
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxsplit


def loss_fn(n_steps: int, checkpointed: bool, m0s):
    target = jnp.asarray(jaxsplit.STANDARD_CASE.reference)

    def loss(log_inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.exp(log_inertia)), "strang")

        def final(m0):
            if checkpointed:
                return jaxsplit.integrate_checkpointed(step, m0, 0.01, n_steps)
            return jaxsplit.integrate(step, m0, 0.01, n_steps).final

        return jnp.sum((jax.vmap(final)(m0s) - target) ** 2)

    return loss


def measure(n_steps: int, checkpointed: bool, batch: int, run: bool) -> dict:
    m0s = jnp.asarray(jaxsplit.sweep_cases(states=batch)["m0"])
    x = jnp.log(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    t0 = time.perf_counter()
    compiled = jax.jit(jax.grad(loss_fn(n_steps, checkpointed, m0s))).lower(x).compile()
    compile_s = time.perf_counter() - t0
    mem = compiled.memory_analysis()
    row = {"n_steps": n_steps, "checkpointed": checkpointed, "batch": batch,
           "temp_bytes": int(mem.temp_size_in_bytes),
           "total_bytes": int(mem.temp_size_in_bytes + mem.argument_size_in_bytes
                              + mem.output_size_in_bytes),
           "compile_s": round(compile_s, 2)}
    if run:
        t0 = time.perf_counter()
        np.asarray(compiled(x))
        row["run_s"] = round(time.perf_counter() - t0, 3)
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[1000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--run", action="store_true", help="also execute the gradients (timing)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = [measure(n, c, args.batch, args.run) for n in args.counts for c in (False, True)]
    if args.json:
        print(json.dumps(rows))
        return
    print(f"{'n_steps':>9} {'checkpoint':>10} {'peak temp MiB':>14} {'total MiB':>10} {'compile s':>9}"
          + (" run s" if args.run else ""))
    for r in rows:
        print(f"{r['n_steps']:>9} {r['checkpointed']!s:>10} {r['temp_bytes'] / 2**20:>14.3f} "
              f"{r['total_bytes'] / 2**20:>10.3f} {r['compile_s']:>9}" + (f" {r['run_s']}" if args.run else ""))
    by = {(r["n_steps"], r["checkpointed"]): r["temp_bytes"] for r in rows}
    ns = sorted(args.counts)
    if len(ns) > 1:
        for c in (False, True):
            slope = np.polyfit(np.log(ns), np.log([max(by[(n, c)], 1) for n in ns]), 1)[0]
            print(f"growth exponent (log-log slope of temp memory vs n), checkpointed={c}: {slope:.2f}")


if __name__ == "__main__":
    main()
