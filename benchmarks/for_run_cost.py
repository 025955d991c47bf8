"""What does ``integrate`` spend beside the run itself on a batch? Its preparation,
``Composition.for_run`` (the rotation kernel chosen from the Casimir bound max|rate|·max|m0|·h,
the batch laid out components-first), against the prepared run, per batch size.

Strang on the Casimir split (standard body, shift 1), h = 0.01, random unit states; 200 steps
for B = 10⁴ and 20 beyond. Columns: ``for_run`` on a fresh device array (no host copy cached);
the prepared run under ``jax.jit``; the whole ``integrate`` call as a user writes it; the
general kernel in the (B, 3) layout (``integrate`` under the caller's ``jit``). Medians of 5.

    python benchmarks/for_run_cost.py

Writes ``benchmarks/results/for_run_cost[-gpu].{md,json}``. On an H100, before the bound was
reduced on the device, ``for_run`` took 95 ms for 10⁶ bodies and 927 ms for 10⁷ (the batch
copied to the host and reduced there, once per flow) against a 7.4 ms run; after, 1.6 and
2.0 ms (``results/for_run_cost-gpu.md``). On the CPU NumPy's ``einsum`` replaced
``linalg.norm`` (10⁷ bodies: 496 ms → 183 ms).
"""

import statistics

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import header, interleaved, machine_info, write

import jaxsplit

H = 0.01
BATCHES = (10_000, 100_000, 1_000_000, 10_000_000)


def median_time(fn, rounds: int = 5) -> float:
    fn()  # compiled and warm
    return statistics.median(interleaved({"fn": fn}, rounds)["fn"])


def measure(step, b: int) -> dict:
    n = 20 if b >= 100_000 else 200
    m = jnp.asarray(np.random.default_rng(0).standard_normal((b, 3)))
    m = m / jnp.linalg.norm(m, axis=1, keepdims=True)

    def fresh():  # a new device array: no cached host copy
        return (m + 0.0).block_until_ready()

    copy = median_time(fresh)
    prepared = step.for_run(m, H)
    run = jax.jit(lambda x: jaxsplit.integrate(prepared, x, H, n).final)
    general = jax.jit(lambda x: jaxsplit.integrate(step, x, H, n).final)
    return {"B": b, "steps": n,
            "for_run_s": median_time(lambda: step.for_run(fresh(), H)) - copy,
            "prepared_run_s": median_time(lambda: run(m).block_until_ready()),
            "integrate_s": median_time(lambda: jaxsplit.integrate(step, fresh(), H, n).final.block_until_ready()) - copy,
            "general_jit_s": median_time(lambda: general(m).block_until_ready())}


def main():
    out = machine_info("python benchmarks/for_run_cost.py")
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia)), "strang", "casimir",
                              shift=1)
    rows = []
    for b in BATCHES:
        rows.append(measure(step, b))
        print(rows[-1], flush=True)
    out["rows"] = rows
    lines = header(out, "integrate's preparation beside its run (`benchmarks/for_run_cost.py`)")
    lines += [("Strang, Casimir split, h = 0.01, float64; milliseconds (median of 5) and, for the runs, billion "
               "body-steps per second."), "",
              "| B | steps | for_run | prepared run | integrate (whole call) | general kernel under jit |",
              "|---|---|---|---|---|---|"]
    for r in rows:
        rate = lambda s, r=r: f"{s * 1e3:.3g} ms ({r['B'] * r['steps'] / s / 1e9:.3g} G/s)"
        lines.append(f"| {r['B']:,} | {r['steps']} | {r['for_run_s'] * 1e3:.3g} ms | {rate(r['prepared_run_s'])} | "
                     f"{r['integrate_s'] * 1e3:.3g} ms | {rate(r['general_jit_s'])} |")
    write("for_run_cost", False, out, lines)


if __name__ == "__main__":
    main()
