"""What compiling a loop as one kernel buys: jaxsplit's XLA setting against XLA's default.

``import jaxsplit`` raises XLA's ``xla_cpu_small_while_loop_byte_threshold`` (1 KiB by
default) to 64 KiB, so loops touching less than that per iteration run as one compiled kernel
instead of one dispatched kernel per fused operation (``jaxsplit/_xla_cpu.py``). The flag is
read once per process, so each setting runs in its own process: XLA's default by setting the
option to 1024 in ``XLA_FLAGS`` (a user's own value is left alone), jaxsplit's by not setting
it, and 4 MiB (everything below 10⁵ bodies as one kernel) to show why jaxsplit stops lower;
rounds alternate the three. Per case: compile time, run time (median of the calls in a
round, then median over rounds), the speed-up, and the largest difference between the
settings' results (0 = bit-identical).

    python benchmarks/small_loops.py [--rounds 3]

Writes ``benchmarks/results/small_loops.{md,json}``.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
THRESHOLD = "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={}"


def worker(out_json: str, out_npz: str, calls: int):
    """One process: every case compiled, run ``calls`` times; times and results written."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import jaxsplit

    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)

    def states(b):
        m = jax.random.normal(jax.random.PRNGKey(0), (b, 3))
        return m / jnp.linalg.norm(m, axis=1, keepdims=True)

    def run_of(scheme, x, h, n):  # integrate as users call it: eager, the kernel chosen for the run
        step = jaxsplit.splitting(body, scheme, "casimir")
        return lambda: jaxsplit.integrate(step, x, h, n).final

    x_top = (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97]))
    top_args = (jnp.array([1.0, 1.0, 0.5]), jnp.array([0.0, 0.0, 0.3]), jnp.asarray(1.5), x_top)

    def top_loss(adjoint):
        def loss(inertia, chi, weight, x0):
            step = jaxsplit.splitting(jaxsplit.heavy_top(inertia, chi, weight), "strang")
            m, gamma = jaxsplit.integrate(step, x0, 0.01, 100_000, adjoint=adjoint).final
            return jnp.sum(m * jnp.arange(1.0, 4.0)) + jnp.sum(gamma)
        return loss

    top_forward = jax.jit(top_loss("store"))
    top_gradient = jax.jit(jax.grad(top_loss("reversible"), argnums=(0, 1, 2, 3)))
    cases = {
        "one body, Strang, 10⁵ steps": run_of("strang", m0, 0.01, 100_000),
        "one body, Kahan–Li 8, 10⁵ steps": run_of("kahan-li-8", m0, 0.01, 100_000),
        "256 bodies, McLachlan SS15, 2,000 steps": run_of("mclachlan-ss15", states(256), 0.05, 2000),
        "256 bodies, Kahan–Li 8, 2,000 steps": run_of("kahan-li-8", states(256), 0.05, 2000),
        "10⁴ bodies, Strang, 1,000 steps": run_of("strang", states(10_000), 0.05, 1000),
        "10⁵ bodies, Strang, 200 steps": run_of("strang", states(100_000), 0.05, 200),
        "heavy top, forward, 10⁵ steps": lambda: top_forward(*top_args),
        "heavy top, reversible gradient, 10⁵ steps": lambda: top_gradient(*top_args),
    }
    times, results = {}, {}
    for name, run in cases.items():
        t0 = time.perf_counter()
        result = jax.block_until_ready(run())
        first = time.perf_counter() - t0
        runs = []
        for _ in range(calls):
            t0 = time.perf_counter()
            jax.block_until_ready(run())
            runs.append(time.perf_counter() - t0)
        times[name] = {"first_call_s": first, "run_s": statistics.median(runs)}
        for k, leaf in enumerate(jax.tree_util.tree_leaves(result)):
            results[f"{name}|{k}"] = np.asarray(leaf)
    np.savez(out_npz, **results)
    Path(out_json).write_text(json.dumps({"times": times, "setting": jaxsplit.small_loop_setting()}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--calls", type=int, default=5)
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(*args.worker, args.calls)

    sys.path.insert(0, str(HERE))
    from _common import fmt, header, log, machine_info, write

    t_start = time.perf_counter()
    settings = {"XLA default (1 KiB)": THRESHOLD.format(1024), "jaxsplit (64 KiB)": None,
                "4 MiB": THRESHOLD.format(4 * 2**20)}
    runs = {name: [] for name in settings}
    arrays = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for k, (name, flags) in enumerate(settings.items()):
                env = {key: value for key, value in os.environ.items() if key != "XLA_FLAGS"}
                if flags:
                    env["XLA_FLAGS"] = flags
                js, npz = f"{tmp}/{r}-{k}.json", f"{tmp}/{r}-{k}.npz"
                subprocess.run([sys.executable, __file__, "--worker", js, npz, "--calls", str(args.calls)],
                               env=env, check=True)
                runs[name].append(json.loads(Path(js).read_text()))
                arrays[name] = dict(np.load(npz))
                log(f"round {r + 1}/{args.rounds}, {name}: {runs[name][-1]['setting']}")
    base, *others = runs
    cases = list(runs[base][0]["times"])

    def median(case_runs, case, key):
        return statistics.median(run["times"][case][key] for run in case_runs)

    out = machine_info("python benchmarks/small_loops.py")
    out.update(settings={name: case_runs[0]["setting"] for name, case_runs in runs.items()}, cases={})
    lines = header(out, "Small loops as one kernel (`benchmarks/small_loops.py`)") + [
        (f"Median over {args.rounds} alternating rounds of the median of {args.calls} calls; each setting in its own "
         f"process. Run time per setting, in brackets the speed-up over {base}; first call = compilation and one "
         f"run; difference: largest |difference| from {base}'s results (0 = bit-identical)."), "",
        "| case | " + " | ".join(f"run, {name}" for name in runs) + " | "
        + " | ".join(f"first call, {name}" for name in runs) + " | difference |",
        "|---|" + "---|" * (2 * len(runs) + 1)]
    for case in cases:
        keys = [key for key in arrays[base] if key.split("|")[0] == case]
        difference = max(float(np.max(np.abs(arrays[base][key] - arrays[name][key]))) for key in keys for name in others)
        entry = {name: {key: median(case_runs, case, key) for key in ("run_s", "first_call_s")}
                 for name, case_runs in runs.items()}
        for name in others:
            entry[name]["speed_up"] = entry[base]["run_s"] / entry[name]["run_s"]
        entry["difference"] = difference
        out["cases"][case] = entry
        lines.append(f"| {case} | {fmt(entry[base]['run_s'])} | "
                     + " | ".join(f"{fmt(entry[name]['run_s'])} ({entry[name]['speed_up']:.2f}×)" for name in others)
                     + " | " + " | ".join(fmt(entry[name]["first_call_s"]) for name in runs) + f" | {difference:.1e} |")
    forward, gradient = "heavy top, forward, 10⁵ steps", "heavy top, reversible gradient, 10⁵ steps"
    lines += ["", "Heavy top, reversible gradient / forward run: " + ", ".join(
        f"{name} {out['cases'][gradient][name]['run_s'] / out['cases'][forward][name]['run_s']:.2f}×"
        for name in settings) + ".", "", f"Total wall time {time.perf_counter() - t_start:.0f} s."]
    write("small_loops", False, out, lines)


if __name__ == "__main__":
    main()
