"""What jaxsplit's one-kernel loops buy, and where they stop: each case compiled twice in one
process, with its stepping loop tagged to compile as one CPU kernel (``jaxsplit/core/
_one_kernel.py``) and untagged (``ONE_KERNEL_BYTES = -1``: XLA's thunk loop, as before),
then timed in interleaved rounds.

Cases: free bodies (Strang, Kahan–Li 8, Blanes–Casas–Murua 8, Casimir split, h = 0.5) at 1
to 16384 bodies; a heavy top's run and reversible gradient (10⁵ steps) and 256 heavy tops.
Each call is compiled ahead of time (``jax.jit(...).lower(...).compile()``, the step
prepared with ``for_run`` as ``integrate`` does), so the two programs of a case run side by
side. Reported: run time of each (median over rounds), the speed-up, whether the tag was
applied, and the largest difference between the two results (0 = bit-identical).

    python benchmarks/one_kernel.py [--rounds 7] [--bytes B]

``--bytes``: tag up to this state size instead of the library's ``ONE_KERNEL_BYTES`` (to see
where one kernel stops paying: the record is made without it).

Writes ``benchmarks/results/one_kernel.{md,json}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, interleaved, log, machine_info, ready, scheme_label

import jaxsplit
from jaxsplit.core import _one_kernel

SIZES = (1, 64, 256, 1024, 2048, 4096, 16384)
SCHEMES = ("strang", "kahan-li-8", "blanes-casas-murua-8")
WORK = 4e6  # body-rotations per call: each call takes ~2-20 ms


def states(b):
    m = np.random.default_rng(0).standard_normal((b, 3))
    return jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True))


def free_body(scheme, b):
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    x0, h = states(b), 0.5
    step = jaxsplit.splitting(body, scheme, "casimir")
    n = max(20, int(WORK / b / step.flows_per_step))
    return f"{b} free bodies, {scheme_label(scheme)}, {n:,} steps", (lambda x: jaxsplit.integrate(step, x, h, n).final), (x0,)


def heavy_tops():
    top = jaxsplit.heavy_top(jnp.array([1.0, 1.0, 0.5]), jnp.array([0.0, 0.0, 0.3]), 1.5)
    one = (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97]))
    many = jax.tree_util.tree_map(lambda a: a + 0.01 * jnp.arange(256.0)[:, None] * a[::-1], one)
    step = jaxsplit.splitting(top, "strang")

    def loss(inertia, chi, weight, x0):
        s = jaxsplit.splitting(jaxsplit.heavy_top(inertia, chi, weight), "strang")
        m, gamma = jaxsplit.integrate(s, x0, 0.01, 100_000, adjoint="reversible").final
        return jnp.sum(m * jnp.arange(1.0, 4.0)) + jnp.sum(gamma)

    args = (jnp.array([1.0, 1.0, 0.5]), jnp.array([0.0, 0.0, 0.3]), jnp.asarray(1.5), one)
    return [("one heavy top, Strang, 10⁵ steps", lambda x: jaxsplit.integrate(step, x, 0.01, 100_000).final, (one,)),
            ("256 heavy tops, Strang, 2,000 steps", lambda x: jaxsplit.integrate(step, x, 0.01, 2000).final, (many,)),
            ("one heavy top, reversible gradient, 10⁵ steps", jax.grad(loss, argnums=(0, 1, 2, 3)), args)]


def compiled(fn, args, tagged: bool):
    """``fn`` compiled ahead of time with the tag on or off (caches cleared: lowered anew)."""
    _one_kernel.ONE_KERNEL_BYTES = LIMIT if tagged else -1
    jax.clear_caches()
    text = (program := jax.jit(fn).lower(*args).compile()).as_text()
    return program, ('inlineable="false"' in text, "xla_cpu_small_call" in text)


DEFAULT = LIMIT = _one_kernel.ONE_KERNEL_BYTES


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--bytes", type=int, default=None)
    args = parser.parse_args()
    global LIMIT
    LIMIT = DEFAULT if args.bytes is None else args.bytes
    out = machine_info("python benchmarks/one_kernel.py" + ("" if args.bytes is None else f" --bytes {args.bytes}"))
    start = time.perf_counter()
    cases = [free_body(s, b) for s in SCHEMES for b in SIZES] + heavy_tops()
    rows = []
    for name, fn, fn_args in cases:
        (on, tag_on), (off, tag_off) = compiled(fn, fn_args, True), compiled(fn, fn_args, False)
        difference = max(float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
                         for a, b in zip(jax.tree_util.tree_leaves(on(*fn_args)), jax.tree_util.tree_leaves(off(*fn_args))))
        times = interleaved({"on": ready(on, *fn_args), "off": ready(off, *fn_args)}, args.rounds)
        row = {"case": name, "one_kernel_s": statistics.median(times["on"]), "thunks_s": statistics.median(times["off"]),
               "tagged": tag_on[0], "xla_pass": tag_off[1], "difference": difference}
        row["speedup"] = row["thunks_s"] / row["one_kernel_s"]
        rows.append(row)
        log(f"{name}: {row['thunks_s'] * 1e3:.2f} -> {row['one_kernel_s'] * 1e3:.2f} ms ({row['speedup']:.2f}x), "
            f"tagged {tag_on[0]}, XLA's pass {tag_off[1]}, difference {difference:.1e}")
    _one_kernel.ONE_KERNEL_BYTES = DEFAULT
    out["rows"], out["one_kernel_bytes"] = rows, LIMIT
    lines = header(out, "Stepping loops as one kernel (`benchmarks/one_kernel.py`)") + [
        (f"Median over {args.rounds} interleaved rounds. 'Thunks': the loop untagged, as XLA runs it by default (one "
         "dispatched kernel per fused operation per step, unless the process-wide small-loop pass takes it: "
         "'XLA small loops' above). 'One kernel': tagged where the state is at most "
         f"{LIMIT / 1024:g} KiB (`ONE_KERNEL_BYTES`) and its arguments at least "
         "any size (decided at lowering); 'tagged': the compiled program "
         "carries jaxsplit's tag; 'XLA's pass': XLA's own process-wide small-loop pass made a loop of the "
         "untagged program one kernel (the stepping loop itself where the speed-up is 1.00×; a processor's short "
         "loops otherwise). Difference: largest |difference| between the two "
         "results (0 = bit-identical)."), "",
        "| case | thunks | one kernel | speed-up | tagged | XLA's pass | difference |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['thunks_s'] * 1e3:.3g} ms | {r['one_kernel_s'] * 1e3:.3g} ms | "
                     f"**{r['speedup']:.2f}×** | {'yes' if r['tagged'] else 'no'} | {'yes' if r['xla_pass'] else 'no'} | "
                     f"{r['difference']:.1e} |")
    finish("one_kernel" if args.bytes is None else f"one_kernel-{args.bytes}", out, lines, start)


if __name__ == "__main__":
    main()
