"""A late SIGTERM: sent as soon as the run's last output appears, while the process is still
alive. The documented status is 130 (issue 31 measured 0 in 6 runs of 10).

    python benchmarks/late_signal.py --runs 10 [--delay-max 0.3] [--root CHECKOUT]

prints the exit statuses (a run that ended before the signal could be sent is counted apart).
``--delay-max D``: the signal waits a random 0..D s after the file appears (seed 0), so that
it also lands while the process exits.
"""

import argparse
import collections
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one(root: Path, delay: float) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=str(root))
        proc = subprocess.Popen([sys.executable, "-m", "jaxsplit", "simulate", "--steps", "30", "--no-figure", "--quiet",
                                 "--out", "run.npz"], cwd=tmp, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        target = Path(tmp) / "run.npz"
        while not target.exists() and proc.poll() is None:
            time.sleep(0.0005)
        time.sleep(delay)
        if proc.poll() is not None:
            return f"ended first ({proc.returncode})"
        proc.send_signal(signal.SIGTERM)
        return str(proc.wait())


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--delay-max", type=float, default=0.0)
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    args = parser.parse_args()
    rng = random.Random(0)
    counts = collections.Counter(one(args.root, rng.uniform(0, args.delay_max)) for _ in range(args.runs))
    print(f"{args.root}: " + ", ".join(f"exit {k}: {v}" for k, v in sorted(counts.items())))


if __name__ == "__main__":
    main()
