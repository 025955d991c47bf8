"""How long does a user wait before a long run starts? Time to the first result of
``integrate`` per scheme and split, split into JAX's tracing, lowering and XLA's compilation.

One state of the standard body, h = 0.1, 10⁵ steps saved every 100 (the suite's conservation
run), each scheme on the axes split (three pieces) and the Casimir split (two), each case in
a fresh process so that nothing is cached; the durations come from ``jax.monitoring`` events.
Compilation grows with the number of sub-flows in the program: XLA compiles each sub-flow
as a kernel of its own (behind the barrier that keeps long words from fusing).

    python benchmarks/compile_time.py

Writes ``benchmarks/results/compile_time.{md,json}``.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

CASES = [(s, split) for s in ("strang", "kahan-li-6", "kahan-li-8", "mclachlan-ss15", "blanes-casas-murua-8", "triple-jump-8",
                              "kahan-li-10", "sofroniou-spaletta-10")
         for split in ("axes", "casimir")]

WORKER = """
import collections, json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import jaxsplit
events = collections.Counter()
jax.monitoring.register_event_duration_secs_listener(
    lambda e, d, **k: events.__setitem__(e.rsplit("/", 1)[-1], events[e.rsplit("/", 1)[-1]] + d))
body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)
jnp.zeros(3).block_until_ready()
events.clear()
step = jaxsplit.splitting(body, sys.argv[1], sys.argv[2])
t0 = time.perf_counter()
jaxsplit.integrate(step, m0, 0.1, 100_000, save_every=100).x.block_until_ready()
first = time.perf_counter() - t0
t0 = time.perf_counter()
jaxsplit.integrate(step, m0, 0.1, 100_000, save_every=100).x.block_until_ready()
print(json.dumps({"first_s": first, "run_s": time.perf_counter() - t0, "sub_flows_per_step": step.flows_per_step,
                  "trace_s": events["jaxpr_trace_duration"], "lower_s": events["jaxpr_to_mlir_module_duration"],
                  "compile_s": events["backend_compile_duration"]}))
"""


def main():
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _common import finish, header, log, machine_info

    out = machine_info("python benchmarks/compile_time.py")
    start = time.perf_counter()
    out["cases"] = []
    lines = header(out, "Time to the first result (`benchmarks/compile_time.py`)") + [
        ("One state, h = 0.1, 10⁵ steps saved every 100; each case in a fresh process. First call = tracing, "
         "lowering, compilation and the run; the durations from `jax.monitoring`."), "",
        "| scheme | split | sub-flows per step | first call | tracing | lowering | XLA compilation | run |",
        "|---|---|---|---|---|---|---|---|"]
    root = Path(__file__).resolve().parent.parent
    for scheme, split in CASES:
        proc = subprocess.run([sys.executable, "-c", WORKER, scheme, split], capture_output=True, text=True, check=True,
                              cwd=root)
        r = json.loads(proc.stdout.strip().splitlines()[-1]) | {"scheme": scheme, "split": split}
        out["cases"].append(r)
        lines.append(f"| {scheme} | {split} | {r['sub_flows_per_step']} | {r['first_s']:.2f} s | {r['trace_s']:.2f} s | "
                     f"{r['lower_s']:.2f} s | {r['compile_s']:.2f} s | {r['run_s'] * 1e3:.0f} ms |")
        log(lines[-1])
    finish("compile_time", out, lines, start)


if __name__ == "__main__":
    main()
