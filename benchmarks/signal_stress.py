"""Randomized signal stress of the command line (issue 10, acceptance 2).

Each trial starts one CLI run (``simulate``, ``sweep``, ``fit`` or ``paper``, chosen at
random) as a real process and sends it SIGINT or SIGTERM from outside at a random moment
between its start and 1.1 x its uninterrupted duration, then checks the contract:

* exit status 0 (finished first) or 130, never a crash (139 / -11), never a traceback;
* nothing half-written: every file in the run's directory reads back whole, and no
  temporary, lock or staging file of the writer is left;
* no finished work lost: an interrupted ``simulate`` that wrote its trajectory says so and
  the file holds every step it reports; an interrupted ``sweep`` keeps exactly the chunks
  it reports, each proving its inputs, and ``--resume`` then gives results identical bit
  for bit to an uninterrupted run; an interrupted ``paper`` keeps every finished claim as an
  uninterrupted audit measures it, and ``--resume`` completes it to the same records.

Runs come from the fork server of ``tests/signal_harness.py`` (JAX imported once; each
child starts after the imports). A second, smaller set goes through the real entry point
``python -m jaxsplit.cli`` with delays from 0, so it also samples the ~2-5 s while Python
imports ``jaxsplit`` (and JAX), before ``main`` has installed the signal policy.

    python benchmarks/signal_stress.py --trials 40 --entry-trials 8 --seed 0

writes ``benchmarks/results/signal_stress.json`` (every trial) and ``signal_stress.md``.
"""

import argparse
import json
import os
import platform
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from signal_harness import Zygote, leftovers, sigint_at_default

COMMANDS = {
    "simulate": ["simulate", "--steps", "3e6", "--save-every", "1000", "--out", "run.npz", "--quiet"],
    "sweep": ["sweep", "--scheme", "strang", "--states", "24", "--chunk-cases", "4", "--t-end", "20", "--out", "sw",
              "--quiet"],
    "fit": ["fit", "--data", "OBS", "--energy", "0.6", "--json"],
    "paper": ["paper", "--out", "audit", "--claims", "stages,thm4.1"],
}
SIGNALS = ("SIGINT", "SIGTERM")


def _readable(path: Path) -> bool:
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                [z[k] for k in z.files]
            return True
        if path.suffix == ".json":
            json.loads(path.read_text())
            return True
        if path.suffix == ".png":
            data = path.read_bytes()
            return data[:8] == b"\x89PNG\r\n\x1a\n" and data[-8:-4] == b"IEND"
        return path.read_text() != "" if path.suffix == ".md" else True
    except Exception:  # noqa: BLE001 - any failure to read back is what we look for
        return False


def _phase(rc: int, err: str) -> str:
    if rc == 0:
        return "finished before the signal"
    if "after the work was done" in err:
        return "while writing (outputs completed)"
    if "steps; kept what was computed" in err or "chunks are saved" in err:
        return "mid-run (finished chunks written)"
    if err.strip().endswith(("(SIGINT)", "(SIGTERM)")):
        return "abandoned (nothing finished yet)"
    return "other"


def _check(command, run, directory: Path, zygote, reference, commands) -> list[str]:
    """The contract's violations for one trial (empty: it held)."""
    problems = []
    rc, err = run.returncode, run.stderr
    if rc not in (0, 130):
        problems.append(f"exit status {rc}")
    if "Traceback" in err:
        problems.append("traceback")
    if leftovers(directory):
        problems.append(f"leftovers {leftovers(directory)}")
    unreadable = [str(p.relative_to(directory)) for p in directory.rglob("*") if p.is_file() and not _readable(p)]
    if unreadable:
        problems.append(f"unreadable {unreadable}")
    if command == "simulate" and rc == 130:
        out = directory / "run.npz"
        if "(written)" in err or "every output is complete" in err:
            with np.load(out) as z:
                meta = json.loads(str(z["metadata"]))
                if meta["steps_completed"] != int(z["step"][-1]):
                    problems.append("steps_completed disagrees with the saved steps")
        elif out.exists():
            problems.append("a trajectory was written but not reported")
    if command == "sweep" and rc == 130 and "chunks are saved" in err:
        saved = int(err.split(" of ")[0].split()[-1])
        chunks = sorted((directory / "sw").glob("chunk-*.npz"))
        if len(chunks) != saved:
            problems.append(f"{saved} chunks reported, {len(chunks)} on disk")
        resumed = zygote.run(commands["sweep"] + ["--resume"], directory)
        if resumed.returncode != 0:
            problems.append(f"resume failed: {resumed.stderr.strip()}")
        elif not _same_results(directory / "sw" / "results.npz", reference["sweep"]):
            problems.append("resumed results differ from an uninterrupted run")
    if command == "paper" and rc == 130 and (directory / "audit" / "claims.json").exists():
        kept = [r for r in json.loads((directory / "audit" / "claims.json").read_text()) if r["verdict"] != "not run"]
        if any(r != reference["paper"][r["id"]] for r in kept):
            problems.append("a kept claim differs from an uninterrupted audit's")
        resumed = zygote.run(commands["paper"][:3] + ["--resume"], directory)
        records = json.loads((directory / "audit" / "claims.json").read_text())
        if resumed.returncode != 0:
            problems.append(f"resume failed: {resumed.stderr.strip()}")
        elif {r["id"]: r for r in records} != reference["paper"]:
            problems.append("the resumed audit differs from an uninterrupted one")
    if command == "fit" and rc == 130 and run.stdout and "inertia_ratios" not in json.loads(run.stdout):
        problems.append("partial fit output")
    return problems


def _same_results(path: Path, reference: dict) -> bool:
    with np.load(path) as z:
        return all(np.array_equal(z[k], v) for k, v in reference.items())


def _observations(directory: Path) -> Path:
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxsplit.explore._fit_inertia import simulate_observations

    t = np.linspace(0.0, 6.0, 60)
    path = directory / "obs.npz"
    np.savez(path, t=t, m=simulate_observations([1.0, 0.8, 0.6], [0.6, 0.3, 0.74], t, 1e-3))
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=40)
    parser.add_argument("--entry-trials", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "signal_stress"))
    args = parser.parse_args()
    rng = random.Random(args.seed)
    work = Path(tempfile.mkdtemp(prefix="jaxsplit-stress-"))
    obs = _observations(work)
    commands = {k: [str(obs) if a == "OBS" else a for a in v] for k, v in COMMANDS.items()}
    zygote = Zygote(work / "logs")

    # Uninterrupted runs: durations and the reference results.
    durations, reference = {}, {}
    for name, argv in commands.items():
        d = work / f"reference-{name}"
        d.mkdir()
        run = zygote.run(argv, d)
        assert run.returncode == 0, (name, run.stderr)
        durations[name] = run.seconds
        print(f"reference {name}: {run.seconds:.1f} s", flush=True)
        if name == "sweep":
            with np.load(d / "sw" / "results.npz") as z:
                reference["sweep"] = {k: z[k] for k in z.files if k != "metadata"}
        if name == "paper":
            reference["paper"] = {r["id"]: r for r in json.loads((d / "audit" / "claims.json").read_text())}

    trials = []
    for i in range(args.trials):
        name, sig = rng.choice(sorted(commands)), rng.choice(SIGNALS)
        delay = rng.uniform(0.0, 1.1 * durations[name])
        d = work / f"trial-{i:03d}"
        d.mkdir()
        run = zygote.start(commands[name], d)
        time.sleep(delay)
        os.kill(run.pid, getattr(signal, sig))  # a finished child is a zombie until waited for: no error
        run.wait()
        problems = _check(name, run, d, zygote, reference, commands)
        trials.append({"trial": i, "command": name, "signal": sig, "delay_s": round(delay, 3),
                       "returncode": run.returncode, "phase": _phase(run.returncode, run.stderr),
                       "seconds": round(run.seconds, 2), "problems": problems,
                       "stderr_tail": run.stderr.strip().splitlines()[-1:] if run.stderr.strip() else []})
        print(f"{i:3d} {name:8s} {sig:7s} at {delay:6.2f} s -> {run.returncode:4d} {trials[-1]['phase']}"
              + (f"  PROBLEMS {problems}" if problems else ""), flush=True)
    zygote.close()

    # The real entry point, from process start (includes the import window).
    entry = []
    for i in range(args.entry_trials):
        sig = SIGNALS[i % 2]
        delay = rng.uniform(0.0, 8.0)
        d = work / f"entry-{i:03d}"
        d.mkdir()
        start = time.monotonic()
        with sigint_at_default():
            proc = subprocess.Popen([sys.executable, "-m", "jaxsplit.cli", *commands["simulate"]], cwd=d,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                    env={**os.environ, "PYTHONPATH": str(ROOT)})
        time.sleep(delay)
        proc.send_signal(getattr(signal, sig))
        _out, err = proc.communicate()
        rc = proc.returncode
        before_main = rc not in (0, 130) and "jaxsplit:" not in err  # main never ran its policy
        entry.append({"trial": i, "signal": sig, "delay_s": round(delay, 3), "returncode": rc,
                      "traceback": "Traceback" in err, "before_main": before_main,
                      "phase": "before main (importing jaxsplit/JAX)" if before_main else _phase(rc, err),
                      "seconds": round(time.monotonic() - start, 2), "leftovers": leftovers(d)})
        print(f"entry {i}: {sig} at {delay:.2f} s -> {rc} {entry[-1]['phase']}", flush=True)

    record = {
        "command": " ".join(["python", "benchmarks/signal_stress.py", "--trials", str(args.trials), "--entry-trials",
                             str(args.entry_trials), "--seed", str(args.seed)]),
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
        "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "reference_seconds": durations, "trials": trials, "entry_trials": entry,
    }
    results = Path(args.results)
    results.with_suffix(".json").write_text(json.dumps(record, indent=2) + "\n")
    results.with_suffix(".md").write_text(_markdown(record))
    failed = [t for t in trials if t["problems"]]
    print(f"{len(trials)} trials, {len(failed)} with problems; wrote {results}.json/.md")
    return 1 if failed else 0


def _markdown(record) -> str:
    trials = record["trials"]
    lines = ["# Signal stress of the command line", "", f"Command: `{record['command']}` ({record['utc']}).", "",
             "Uninterrupted durations (s): " + ", ".join(f"{k} {v:.1f}" for k, v in record["reference_seconds"].items())
             + ".", "", "| command | signal | phase reached | trials | contract held |", "|---|---|---|---|---|"]
    groups = Counter((t["command"], t["signal"], t["phase"]) for t in trials)
    held = Counter((t["command"], t["signal"], t["phase"]) for t in trials if not t["problems"])
    for key in sorted(groups):
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {groups[key]} | {held[key]} |")
    failed = [t for t in trials if t["problems"]]
    statuses = Counter(t["returncode"] for t in trials)
    lines += ["", (f"**{len(trials)} trials, {len(trials) - len(failed)} held the contract, {len(failed)} did not.** "
              f"Exit statuses: {dict(sorted(statuses.items()))}."), ""]
    for t in failed:
        lines.append(f"- trial {t['trial']} ({t['command']}, {t['signal']} at {t['delay_s']} s): {t['problems']}")
    entry = record["entry_trials"]
    if entry:
        before = [e for e in entry if e["before_main"]]
        lines += ["", "## Through the real entry point (`python -m jaxsplit.cli`), from process start", "",
                  "| trial | signal | at (s) | exit | phase | traceback |", "|---|---|---|---|---|---|"]
        for e in entry:
            lines.append(f"| {e['trial']} | {e['signal']} | {e['delay_s']} | {e['returncode']} | {e['phase']} | "
                         f"{'yes' if e['traceback'] else 'no'} |")
        lines += ["", (f"{len(before)} of {len(entry)} signals arrived before `main` ran (Python importing `jaxsplit`, "
                  "hence JAX): there Python's defaults apply (SIGINT: a KeyboardInterrupt traceback, exit -2 or 1, or "
                  "an abort (-6) when it lands inside an extension module's import; SIGTERM: exit -15), nothing was "
                  "written. This window is outside `jaxsplit/cli`: the console "
                  "script imports the whole package before `main` (see the report of this change)."), ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
