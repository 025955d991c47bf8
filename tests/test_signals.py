"""Acceptance 2 and 3: SIGINT and SIGTERM never lose finished work, never leave a file
half-written, never crash; two runs into one output: one proceeds, the other exits 2.

Real processes (``signal_harness.Zygote``: JAX imported once, one fork per run), one run
per command x signal x phase class, the signal sent by the process to itself at that
phase (deterministic). The randomized stress over arbitrary moments, from outside, is
``benchmarks/signal_stress.py`` (results in ``benchmarks/results/signal_stress.md``).
The policy itself (modes, counting, clean-ups) is unit-tested in-process at the end.
"""

import json
import signal

import jax.numpy as jnp
import numpy as np
import pytest
from signal_harness import Zygote, leftovers

from jaxsplit import PAPER_BODY, RigidBody, splitting
from jaxsplit.cli import _signals
from jaxsplit.cli._chunked import chunk_size

SIMULATE = ["simulate", "--steps", "1e6", "--save-every", "1000", "--quiet"]  # 3 chunks of 333,333 steps
SWEEP = ["sweep", "--scheme", "strang", "--states", "12", "--chunk-cases", "4", "--t-end", "2", "--quiet"]
PAPER = ["paper", "--claims", "stages"]
INTERRUPTED = 130


@pytest.fixture(scope="module")
def zygote(tmp_path_factory):
    z = Zygote(tmp_path_factory.mktemp("logs"))
    yield z
    z.close()


@pytest.fixture(scope="module")
def observations(tmp_path_factory):
    from jaxsplit.explore._fit_inertia import simulate_observations

    t = np.linspace(0.0, 4.0, 40)
    path = tmp_path_factory.mktemp("fit") / "obs.npz"
    np.savez(path, t=t, m=simulate_observations([1.0, 0.8, 0.6], [0.6, 0.3, 0.74], t, 1e-3))
    return path


def _interrupted(run, sig):
    assert run.returncode == INTERRUPTED, (run.returncode, run.stderr)
    assert "Traceback" not in run.stderr and f"interrupted ({sig}" in run.stderr, run.stderr


def _load(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def _complete(path) -> bool:
    """The file reads back whole in its format."""
    if path.suffix == ".npz":
        return bool(_load(path))
    if path.suffix == ".json":
        return bool(json.loads(path.read_text()))
    if path.suffix == ".png":
        return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.read_bytes()[-8:-4] == b"IEND"
    return path.read_text().startswith("# Audit")


# ------------------------------------------------------------------ abandon: nothing finished yet
@pytest.mark.parametrize("command,argv,sig", [
    ("simulate", SIMULATE + ["--out", "run.npz"], "SIGTERM"),
    ("sweep", SWEEP + ["--out", "sw"], "SIGINT"),
])
def test_signal_while_parsing_ends_at_once_with_nothing_written(zygote, tmp_path, command, argv, sig):
    run = zygote.run(argv, tmp_path, trigger="parse", signal=sig)
    _interrupted(run, sig)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_fit_interrupted_inside_xla_exits_130_without_crashing(zygote, tmp_path, observations, sig):
    """The fit segfault: the signal arrives while XLA compiles or runs the optimiser."""
    run = zygote.run(["fit", "--data", observations, "--energy", "0.6"], tmp_path,
                     trigger="during:jaxsplit.explore._fit_inertia:_optimise:0.2", signal=sig)
    _interrupted(run, sig)
    assert run.stdout == "" and run.seconds < 60


def test_check_interrupted_inside_xla_exits_130(zygote, tmp_path):
    run = zygote.run(["check", "--json"], tmp_path, trigger="during:jaxsplit.cli.check:_errors:0.2",
                     signal="SIGTERM")
    _interrupted(run, "SIGTERM")
    assert run.stdout == "" and list(tmp_path.iterdir()) == []


def test_paper_interrupted_mid_audit_keeps_the_finished_claim_and_resumes(zygote, tmp_path):
    """A real process, SIGTERM inside the second claim: the first claim's record is on disk,
    the other marked not run, the user's file untouched; --resume runs only the second.
    (Three moments, compared with an uninterrupted audit: tests/test_audit.py, in-process.)"""
    out = tmp_path / "audit"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    argv = ["paper", "--claims", "ex2.1-i,stages", "--out", out]
    run = zygote.run(argv, tmp_path, trigger="call:jaxsplit.paper._audit:_run_claim:2", signal="SIGTERM")
    _interrupted(run, "SIGTERM")
    assert "1 of 2 claims are saved" in run.stderr and "--resume" in run.stderr, run.stderr
    first = json.loads((out / "claims.json").read_text())
    assert [r["verdict"] for r in first][1] == "not run" and first[0]["verdict"] != "not run"
    assert sorted(p.name for p in out.iterdir()) == ["claims.json", "notes.txt", "report.md"]
    run = zygote.run(["paper", "--out", out, "--resume"], tmp_path)
    assert run.returncode == 0, run.stderr
    final = json.loads((out / "claims.json").read_text())
    assert final[0] == first[0] and final[1]["verdict"] == "corrected"
    assert "Kept from an earlier run (resumed): ex2.1-i." in (out / "report.md").read_text()
    assert (out / "notes.txt").read_text() == "mine" and leftovers(tmp_path) == []


# ------------------------------------------------------------------ defer: finished chunks are kept
def test_simulate_stopped_mid_run_writes_the_finished_chunks(zygote, tmp_path):
    run = zygote.run(SIMULATE + ["--out", "run.npz", "--no-figure"], tmp_path,
                     trigger="call:jaxsplit.core._integrate:integrate:2", signal="SIGINT")
    _interrupted(run, "SIGINT")
    z = _load(tmp_path / "run.npz")
    meta = json.loads(str(z["metadata"]))
    chunk = chunk_size(10**6, 1000, splitting(RigidBody(jnp.asarray(PAPER_BODY)), "lie-trotter").flows_per_step)
    assert meta["status"] == "interrupted" and meta["steps_completed"] == z["step"][-1] == 2 * chunk < 10**6
    assert np.all(np.isfinite(z["m"])) and sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]


def test_sweep_stopped_mid_run_keeps_its_proven_chunks(zygote, tmp_path):
    from jaxsplit.cli.sweep import _inputs_digest, _proven_chunk

    run = zygote.run(SWEEP + ["--out", "sw"], tmp_path, trigger="call:jaxsplit.explore._sweep:sweep:2",
                     signal="SIGTERM")
    _interrupted(run, "SIGTERM")
    assert "2 of 3 chunks are saved" in run.stderr and "--resume" in run.stderr
    out = tmp_path / "sw"
    chunks = sorted(out.glob("chunk-*"))
    assert [p.name for p in chunks] == ["chunk-00000.npz", "chunk-00001.npz"]
    digest = _inputs_digest(json.loads((out / "manifest.json").read_text())["inputs"])
    cases = _load(out / "cases.npz")
    for k, path in enumerate(chunks):  # each finished chunk is whole and proves its inputs
        assert _proven_chunk(path, 4 * k, 4 * k + 4, cases, digest) is not None
    assert not (out / "results.npz").exists() and leftovers(tmp_path) == []


# ------------------------------------------------------------------ critical: outputs complete
@pytest.mark.parametrize("argv,trigger,sig,outputs", [
    (SIMULATE[:1] + ["--steps", "300", "--out", "run.npz"], "call:jaxsplit.cli._io:Outputs.write:1", "SIGTERM",
     ["run.npz", "run.png"]),
    (SWEEP + ["--out", "sw"], "call:jaxsplit.cli._io:Outputs.write:6", "SIGINT",
     ["sw/results.npz", "sw/summary.json"]),
    (PAPER + ["--out", "audit"], "call:jaxsplit.cli._io:Outputs.write:3", "SIGINT",  # 1, 2: "not run" yet
     ["audit/claims.json", "audit/report.md"]),
], ids=["simulate", "sweep", "paper"])
def test_signal_while_writing_completes_every_output(zygote, tmp_path, argv, trigger, sig, outputs):
    run = zygote.run(argv, tmp_path, trigger=trigger, signal=sig)
    _interrupted(run, sig)
    assert "after the work was done; every output is complete" in run.stderr
    for name in outputs:
        assert _complete(tmp_path / name), name
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_fit_interrupted_while_printing_prints_the_whole_result(sig, monkeypatch, capsys, tmp_path, observations):
    """In-process with a real signal (the printing is critical: only recorded); the fit itself
    is replaced by a precomputed result so that no optimiser compiles here (test_fit does that)."""
    import os

    import jaxsplit.cli.fit as fit_cli
    from jaxsplit.explore._fit_inertia import FitResult

    done = FitResult(inertia=np.ones(3), inertia_ratios=np.ones(2), ratio_std=np.ones(2),
                     inverse_differences=np.ones(2), inverse_differences_std=np.ones(2), m0=np.ones(3), loss=1.0,
                     noise_sigma=1.0, iterations=1, gauge="energy", ratio_range=np.ones((2, 2)),
                     null_direction=np.ones(3), null_alignment=1.0, hessian_eigenvalues=np.ones(3), seconds=0.0)
    monkeypatch.setattr(fit_cli, "fit_inertia", lambda *a, **k: done)
    real_print = fit_cli._print

    def print_under_signal(*args):
        os.kill(os.getpid(), sig)
        real_print(*args)

    monkeypatch.setattr(fit_cli, "_print", print_under_signal)
    from jaxsplit.cli import main

    assert main(["fit", "--data", str(observations), "--json"]) == INTERRUPTED
    captured = capsys.readouterr()
    assert json.loads(captured.out)["inertia_ratios"] == [1.0, 1.0]
    assert captured.err.strip().endswith("after the work was done; every output is complete")


@pytest.mark.parametrize("sig,moment", [("SIGINT", "end_process"), ("SIGTERM", "end_process"),
                                        ("SIGTERM", "Policy._late_signal")], ids=["SIGINT", "SIGTERM", "SIGTERM-deciding"])
def test_a_signal_after_the_last_output_exits_130(zygote, tmp_path, sig, moment):
    """A late signal (the last file written, the status decided, the process still alive)
    gives the documented 130, never 0: when ``end_process`` begins and while it decides the
    status (once it exited 0 in 6 runs of 10, and later, with the signals blocked there, once in
    CI)."""
    run = zygote.run(SIMULATE[:1] + ["--steps", "30", "--no-figure", "--quiet", "--out", "run.npz"], tmp_path,
                     trigger=f"call:jaxsplit.cli._signals:{moment}:1", signal=sig)
    _interrupted(run, sig)
    assert _complete(tmp_path / "run.npz") and leftovers(tmp_path) == []


# ------------------------------------------------------------------ concurrency
@pytest.mark.parametrize("argv", [SWEEP + ["--out", "shared"],
                                  SIMULATE[:1] + ["--steps", "2e6", "--save-every", "1000", "--no-figure", "--out", "x.npz"]],
                         ids=["sweep", "simulate"])
def test_two_runs_into_one_output_one_proceeds_the_other_exits_2(zygote, tmp_path, argv):
    first, second = zygote.start(argv, tmp_path), zygote.start(argv, tmp_path)
    runs = sorted([first.wait(), second.wait()], key=lambda r: r.returncode)
    assert [r.returncode for r in runs] == [0, 2], [r.stderr for r in runs]
    loser = runs[1].stderr
    assert loser.count("\n") == 1 and ("in use by another jaxsplit run" in loser or "exists" in loser
                                       or "already holds a sweep" in loser), loser
    assert leftovers(tmp_path) == []


# ------------------------------------------------------------------ the policy, in-process
class _Exit(Exception):
    pass


@pytest.fixture
def policy(monkeypatch):
    def fake_exit(code):
        raise _Exit(code)

    monkeypatch.setattr(_signals.os, "_exit", fake_exit)
    return _signals.Policy()


def test_policy_abandons_by_default_after_its_cleanups(policy, capfd):
    cleaned = []
    with policy.cleanup(lambda: cleaned.append(1)), pytest.raises(_Exit) as stopped:
        policy._signalled(bytes([signal.SIGTERM]))
    assert stopped.value.args == (130,) and cleaned == [1]
    assert capfd.readouterr().err == "jaxsplit: interrupted (SIGTERM)\n"


def test_policy_defers_once_then_abandons_and_never_abandons_while_writing(policy):
    with policy.defer():
        policy._signalled(bytes([signal.SIGINT]))
        assert policy.requested and policy.received == signal.SIGINT
        with pytest.raises(_signals.Interrupted):
            policy.check()
        with policy.critical():
            policy._signalled(bytes([signal.SIGINT, signal.SIGTERM]))  # only recorded
        with pytest.raises(_Exit):
            policy._signalled(bytes([signal.SIGINT]))  # a further signal outside the write: abandon
    with pytest.raises(_Exit):
        _signals.Policy()._signalled(bytes([signal.SIGTERM]))  # the default mode abandons


def test_policy_keeps_an_ignored_sigint_ignored(monkeypatch):
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _signals.policy():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    finally:
        signal.signal(signal.SIGINT, previous)


def test_importing_the_command_line_loads_no_jax():
    """The console script imports ``jaxsplit.cli`` before ``main`` installs the signal policy:
    that import must be light (no JAX, no NumPy), so no interrupt can land in a heavy import
    outside the policy. Importing the library itself starts no JAX backend (import-time
    arrays start XLA's threads; a forked CLI child then deadlocks)."""
    import subprocess
    import sys

    code = ("import importlib, sys, jaxsplit.cli\n"
            "print(sorted(m for m in ('jax', 'numpy') if m in sys.modules))\n"
            "import jaxsplit\n"
            "jaxsplit.integrate  # loads every public name\n"
            "for n in ('simulate', 'sweep', 'check', 'fit', 'paper', 'schemes'):\n"
            "    importlib.import_module('jaxsplit.cli.' + n)\n"
            "from jax._src import xla_bridge\n"
            "print(sorted(xla_bridge._backends))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]", "[]"], out.stdout


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_signal_while_jax_is_imported_exits_130_without_traceback(tmp_path, sig):
    """Ctrl-C during the first second of a run (JAX importing): the policy already holds."""
    import subprocess
    import sys

    code = ("import builtins, os, signal, sys\n"
            "real_import = builtins.__import__\n"
            "def importing(name, *args, **kwargs):\n"
            "    if name == 'jax' and 'jax' not in sys.modules:\n"
            f"        os.kill(os.getpid(), signal.{sig})\n"
            "    return real_import(name, *args, **kwargs)\n"
            "builtins.__import__ = importing\n"
            "from jaxsplit.cli import main  # what the console script does\n"
            "sys.argv = ['jaxsplit', 'simulate', '--steps', '10', '--out', 'run.npz']\n"
            "sys.exit(main())")
    import os
    from pathlib import Path

    env = dict(os.environ, PYTHONPATH=f"{Path(__file__).resolve().parents[1]}{os.pathsep}"
                                       f"{os.environ.get('PYTHONPATH', '')}")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                         check=False, timeout=120)
    _interrupted(run, sig)
    assert list(tmp_path.iterdir()) == []
