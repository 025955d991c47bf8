"""Is the direct batched call as fast as before a commit? The same workload run by this tree and
by an earlier commit (default 2431e1a, the last commit before issue 30's one-kernel-for-every-
angle rewrite), each in its own process, in interleaved rounds.

The workload: 256 free bodies (standard body, Casimir split), ``integrate(step, batch, h, n).final``
called directly, per scheme; the CPU time of one call (``time.process_time``: other jobs' load
does not inflate it), the least of 7 calls after a warm-up, per process. This tree runs twice:
as imported (XLA's 256-bit vectors) and after ``jaxsplit.tune_cpu()`` (512-bit vectors, the
explicit call that replaced the import-time setting). The earlier commit runs as it imports
(before 3cd299b it set its XLA flags on import). The earlier tree is checked out with
``git worktree`` into a temporary directory and removed afterwards.

    python benchmarks/against_before.py [--commit 2431e1a] [--rounds 3] [--quick]

Writes ``benchmarks/results/against_before.{md,json}``.
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

from _common import finish, header, log, machine_info

ROOT = Path(__file__).resolve().parents[1]
CASES = (("strang", 10_000), ("kahan-li-8", 2_000), ("blanes-casas-murua-8", 1_800))

# One process: the least CPU time of 7 calls of each case, printed as JSON.
CHILD = r"""
import json, os, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jaxsplit
if os.environ.get("JAXSPLIT_TUNE"):
    jaxsplit.tune_cpu()
import jax.numpy as jnp, numpy as np
rng = np.random.default_rng(0)
m0 = rng.normal(size=(256, 3)); m0 = jnp.asarray(m0 / np.linalg.norm(m0, axis=1, keepdims=True))
out = {}
for scheme, n in json.loads(sys.argv[1]):
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2 / 3]), allow_nonphysical=True), scheme, "casimir")
    call = lambda: jax.block_until_ready(jaxsplit.integrate(step, m0, 1000.0 / n, n).final)
    call()
    best = float("inf")
    for _ in range(7):
        t = time.process_time(); call(); best = min(best, time.process_time() - t)
    out[scheme] = best
print(json.dumps(out))
"""


def run(tree: Path, cases, tune: bool) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), JAXSPLIT_TUNE="1" if tune else "")
    done = subprocess.run([sys.executable, "-c", CHILD, json.dumps(cases)], cwd=tree, env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commit", default="2431e1a")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    cases = [(s, n // 10 if args.quick else n) for s, n in CASES]
    command = "python benchmarks/against_before.py" + (f" --commit {args.commit}" if args.commit != "2431e1a" else "") \
        + (f" --rounds {args.rounds}" if args.rounds != 3 else "") + (" --quick" if args.quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        before = Path(tmp) / "before"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(before), args.commit], cwd=ROOT, check=True)
        try:
            contenders = {f"{args.commit} (as imported)": (before, False), "this tree (as imported)": (ROOT, False),
                          "this tree, tune_cpu()": (ROOT, True)}
            times = {name: [] for name in contenders}
            for r in range(args.rounds):
                for name, (tree, tune) in contenders.items():
                    times[name].append(run(tree, cases, tune))
                log(f"round {r + 1}: " + ", ".join(f"{k}: {v[-1]}" for k, v in times.items()))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT, check=False)
    rows = []
    for scheme, n in cases:
        row = {"scheme": scheme, "n_steps": n}
        for name in contenders:
            row[name] = statistics.median(t[scheme] for t in times[name])
        rows.append(row)
    out.update(commit_before=args.commit, rows=rows)
    names = list(contenders)
    lines = header(out, "The direct batched call against an earlier commit (`benchmarks/against_before.py`)")
    lines += [("256 free bodies, standard body, Casimir split, `integrate(step, batch, h, n).final` called directly; CPU "
               f"ms of one call (least of 7 per process, median over {args.rounds} interleaved rounds of fresh processes), "
               "and this tree's time over the earlier commit's."), "",
              "| scheme | steps | " + " | ".join(names) + " | × as imported | × with tune_cpu() |",
              "|---|---|" + "---|" * (len(names) + 2)]
    for r in rows:
        base = r[names[0]]
        lines.append(f"| {r['scheme']} | {r['n_steps']:,} | " + " | ".join(f"{r[k] * 1e3:.2f}" for k in names)
                     + f" | {r[names[1]] / base:.2f} | {r[names[2]] / base:.2f} |")
    finish("against_before", out, lines, start, args.quick)


if __name__ == "__main__":
    main()
