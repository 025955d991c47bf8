"""Acceptance 2 (CLI): a sweep killed part-way (Ctrl-C = SIGINT, or SIGKILL) and resumed
with ``--resume`` yields results identical (bit for bit) to an uninterrupted run; no
finished chunk is recomputed or lost.

The uninterrupted run and the resumptions run in-process (one compilation); the runs that
are killed are real subprocesses, killed once a few chunk files exist.
"""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxsplit.cli import main

# 40 chunks of 4 cases, 20 000 steps each: long enough to kill part-way, one compilation.
ARGS = ["sweep", "--scheme", "lie-trotter", "--reference-scheme", "strang", "--states", "160",
        "--ratios", "1,0.5", "--dt", "0.01", "--t-end", "200", "--chunk-cases", "4", "--quiet"]
N_CHUNKS = 40
KILL_AFTER_CHUNKS = 3
TIMEOUT = 120


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "whole"
    assert main(ARGS + ["--out", str(out)]) == 0
    return out


def _chunks(out):
    return sorted(out.glob("chunk-*.npz"))


def _kill_part_way(out, sig):
    """Start the sweep in a subprocess and send ``sig`` once some chunk files exist."""
    proc = subprocess.Popen([sys.executable, "-m", "jaxsplit.cli", *ARGS, "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + TIMEOUT
    while len(_chunks(out)) < KILL_AFTER_CHUNKS if out.exists() else True:
        assert proc.poll() is None, f"sweep ended before it could be killed: {proc.communicate()}"
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=TIMEOUT)
    return proc.returncode, stdout, stderr


def _results(out):
    with np.load(out / "results.npz") as z:
        return {k: z[k] for k in z.files if k != "metadata"}


def _assert_identical(a, b):
    ra, rb = _results(a), _results(b)
    assert ra.keys() == rb.keys()
    for key in ra:
        assert ra[key].dtype == rb[key].dtype and np.array_equal(ra[key], rb[key]), key
    for ca, cb in zip(_chunks(a), _chunks(b), strict=True):
        with np.load(ca) as za, np.load(cb) as zb:
            assert all(np.array_equal(za[k], zb[k]) for k in za.files)


def _stamp(paths):
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in paths}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_killed_sweep_resumes_to_identical_results(sig, uninterrupted, tmp_path, capsys):
    out = tmp_path / "killed"
    rc, _, stderr = _kill_part_way(out, sig)
    if sig == signal.SIGINT:
        assert rc == 130 and "--resume" in stderr and "Traceback" not in stderr
    else:
        assert rc == -signal.SIGKILL
    done = _chunks(out)
    assert KILL_AFTER_CHUNKS <= len(done) < N_CHUNKS
    assert not (out / "results.npz").exists()
    before = _stamp(done)

    capsys.readouterr()
    assert main(ARGS + ["--out", str(out), "--resume", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chunks_skipped"] == len(done)  # finished chunks were not recomputed ...
    assert summary["chunks_computed"] == N_CHUNKS - len(done)
    assert {k: v for k, v in _stamp(_chunks(out)).items() if k in before} == before  # ... nor rewritten
    assert len(_chunks(out)) == N_CHUNKS
    assert not list(out.glob(".*.tmp"))  # temporary files of the killed run are gone
    _assert_identical(out, uninterrupted)


def test_resume_of_a_finished_sweep_computes_nothing(uninterrupted, tmp_path, capsys):
    out = tmp_path / "copy"
    out.mkdir()
    for p in uninterrupted.iterdir():
        (out / p.name).write_bytes(p.read_bytes())
    capsys.readouterr()
    assert main(ARGS + ["--out", str(out), "--resume", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chunks_computed"] == 0 and summary["chunks_skipped"] == N_CHUNKS
    _assert_identical(out, uninterrupted)


def test_corrupt_chunk_is_recomputed(uninterrupted, tmp_path, capsys):
    out = tmp_path / "corrupt"
    out.mkdir()
    for p in uninterrupted.iterdir():
        if p.name != "results.npz":
            (out / p.name).write_bytes(p.read_bytes())
    victim = _chunks(out)[5]
    victim.write_bytes(victim.read_bytes()[:100])  # e.g. a copy cut short by a full disk
    os.remove(_chunks(out)[7])
    capsys.readouterr()
    assert main(ARGS + ["--out", str(out), "--resume", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["chunks_computed"] == 2
    _assert_identical(out, uninterrupted)


def test_resume_refuses_different_inputs(uninterrupted, capsys):
    changed = [a if a != "200" else "100" for a in ARGS]  # --t-end 100
    assert main(changed + ["--out", str(uninterrupted), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "different inputs" in err and "t_end: was 200.0, now 100.0" in err


def test_results_hold_the_cases_and_the_library_results(uninterrupted):
    from jaxsplit import sweep, sweep_cases

    with np.load(uninterrupted / "results.npz") as z:
        results = {k: z[k] for k in z.files}
    meta = json.loads(str(results.pop("metadata")))
    assert meta["inputs"]["scheme"] == "lie-trotter" and meta["inputs"]["t_end"] == 200.0
    cases = sweep_cases(states=160, ratios=[(1.0, 0.5)], step_sizes=[0.01], dtype=np.float64)
    for key, value in cases.items():
        np.testing.assert_array_equal(results[f"case_{key}"], value)
    # Chunk 7 equals the library called directly on the same slice of cases.
    piece = {k: v[28:32] for k, v in cases.items()}
    direct = sweep("lie-trotter", piece, t_end=200.0, reference_scheme="strang", chunk_size=4,
                   reference_angle=meta["inputs"]["reference_angle"])
    for key, value in direct.items():
        np.testing.assert_array_equal(results[key][28:32], value)
    summary = json.loads((uninterrupted / "summary.json").read_text())
    assert summary["cases"] == 160 and summary["energy_error"]["max"] == np.max(results["energy_error"])
