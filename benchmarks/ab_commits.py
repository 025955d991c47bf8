"""A/B: the library's throughput at another commit against this tree, interleaved.

Checks out ``--base`` (default: the commit before the system layer) into a temporary git
worktree and runs ``benchmarks/throughput.py --quick`` alternately there and here, each in
its own process with its own ``jaxsplit`` first on ``PYTHONPATH`` (``--rounds`` times each,
old first), so load from other jobs hits both sides alike. Reports, for every
``jaxsplit ...`` row of the single-trajectory table, the median ns per rotation and compile
time on each side and the median of the per-round ratios new / old.

    python benchmarks/ab_commits.py                      # base a5760b9, 3 rounds
    python benchmarks/ab_commits.py --base HEAD~3 --rounds 5

Writes ``benchmarks/results/ab_commits.{json,md}``.
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

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
DEFAULT_BASE = "a5760b9"


def run_side(tree: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, "throughput.py", "--quick"], cwd=tree / "benchmarks", env=env, check=True,
                   stdout=subprocess.DEVNULL)
    data = json.loads((tree / "benchmarks" / "results" / "throughput-quick.json").read_text())
    return {r["method"]: r for r in data["single"]["rows"] if r["method"].startswith("jaxsplit ")}


def git(*args) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True).stdout.strip()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default=DEFAULT_BASE, help=f"the old commit (default {DEFAULT_BASE})")
    parser.add_argument("--rounds", type=int, default=3, help="runs per side, interleaved (default 3)")
    args = parser.parse_args(argv)
    base = git("rev-parse", "--short", args.base)
    head = git("rev-parse", "--short", "HEAD")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="jaxsplit-ab-") as tmp:
        old_tree = Path(tmp) / "old"
        git("worktree", "add", "--detach", str(old_tree), base)
        try:
            rounds = []
            for k in range(args.rounds):
                old = run_side(old_tree)
                new = run_side(ROOT)
                rounds.append((old, new))
                print(f"round {k + 1}/{args.rounds} done", file=sys.stderr)
        finally:
            git("worktree", "remove", "--force", str(old_tree))
    methods = [m for m in rounds[0][1] if m in rounds[0][0]]
    table = []
    for m in methods:
        old_ns = [o[m]["ns_per_rotation"] for o, _ in rounds]
        new_ns = [n[m]["ns_per_rotation"] for _, n in rounds]
        table.append({
            "method": m,
            "old_ns_per_rotation": statistics.median(old_ns), "new_ns_per_rotation": statistics.median(new_ns),
            "ratio_new_over_old": statistics.median(n / o for o, n in zip(old_ns, new_ns)),
            "old_compile_s": statistics.median(o[m]["compile_s"] for o, _ in rounds),
            "new_compile_s": statistics.median(n[m]["compile_s"] for _, n in rounds),
        })
    out = {"command": "python benchmarks/ab_commits.py " + " ".join(argv or sys.argv[1:]), "base": base,
           "head": head, "rounds": args.rounds, "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "rows": table, "wall_s": time.perf_counter() - start}
    title = f"# A/B: `{base}` (old) against `{head}` (new), `throughput.py --quick`, {args.rounds} interleaved rounds"
    lines = [title, "", f"`{out['command']}` ({out['date_utc']}, {out['wall_s']:.0f} s)", "",
             "| method | old ns/rotation | new ns/rotation | new / old (median of rounds) | old compile | new compile |",
             "|---|---|---|---|---|---|"]
    for r in table:
        lines.append(f"| {r['method']} | {r['old_ns_per_rotation']:.1f} | {r['new_ns_per_rotation']:.1f} | "
                     f"{r['ratio_new_over_old']:.3f} | {r['old_compile_s']:.2f} s | {r['new_compile_s']:.2f} s |")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ab_commits.json").write_text(json.dumps(out, indent=1))
    (RESULTS / "ab_commits.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
