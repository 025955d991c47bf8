"""Acceptance 1 (CLI): bad invocations get exit status 2, ONE line on stderr naming the
value and what is allowed, nothing on stdout and no traceback; nothing is run or written.

Most run in-process through ``jaxsplit.cli.main`` (fast); two go through a real
subprocess to prove the installed entry point prints no traceback either.
"""

import os
import subprocess
import sys

import pytest

from jaxsplit.cli import main

# (argv, words the one-line message must contain: the value and/or what is allowed)
SIMULATE = [
    (["--inertia", "0,1,1"], ["--inertia", "positive"]),
    (["--inertia", "-1,1,1"], ["--inertia", "positive"]),
    (["--inertia", "nan,1,1"], ["--inertia", "finite"]),
    (["--inertia", "inf,1,1"], ["--inertia", "finite"]),
    (["--inertia", "1,1,3"], ["not a physical body", "I1 + I2 >= I3", "--allow-nonphysical"]),
    (["--inertia", "1,2"], ["--inertia", "3 comma-separated", "'1,2'"]),
    (["--inertia", "a,b,c"], ["--inertia", "'a' is not a number"]),
    (["--m0", "1,2,3,4"], ["--m0", "3 comma-separated"]),
    (["--m0", "nan,0,1"], ["--m0", "finite"]),
    (["--m0", "inf,0,0"], ["--m0", "finite"]),
    (["--m0", "1e200,1e200,0"], ["--m0", "overflows"]),
    (["--dt", "0"], ["--dt", "non-zero"]),
    (["--dt", "nan"], ["--dt", "non-zero"]),
    (["--steps", "0"], ["--steps", "positive integer"]),
    (["--steps", "-5"], ["--steps", "positive integer"]),
    (["--steps", "2.5"], ["--steps", "positive integer", "'2.5'"]),
    (["--t-end", "0"], ["--t-end", "positive"]),
    (["--steps", "10", "--t-end", "1"], ["--t-end", "not allowed with", "--steps"]),
    (["--save-every", "0"], ["--save-every", "positive integer"]),
    (["--scheme", "stang"], ["unknown scheme 'stang'", "did you mean", "strang"]),
    (["--scheme", "blanes-moan-s6-prk", "--split", "axes"], ["blanes-moan-s6-prk", "--split casimir"]),
    (["--split", "diagonal"], ["--split", "invalid choice", "'diagonal'"]),
    (["--split", "axes", "--shift-axis", "2"], ["--shift-axis", "--split casimir"]),
    (["--out", "/nonexistent-dir-jaxsplit/run.npz"], ["/nonexistent-dir-jaxsplit", "does not exist"]),
    (["--out", "/proc/jaxsplit-run.npz"], ["cannot write", "/proc/jaxsplit-run.npz"]),
    (["--out", "run.txt"], ["run.txt", ".npz or .csv"]),
    (["--out", "run.csv", "--format", "npz"], ["--format npz", "conflicts"]),
    (["--steps", "1e9", "--max-memory", "1M"], ["GiB", "--max-memory", "--save-every"]),
    (["--max-memory", "lots"], ["--max-memory", "500M"]),
    (["--frobnicate"], ["unrecognized arguments", "--frobnicate"]),
    (["--no-save", "--out", "x.npz"], ["--no-save", "--out"]),
]
OTHERS = [
    (["frobnicate"], ["invalid choice", "'frobnicate'"]),
    (["check", "--scheme", "kahan-li-7"], ["unknown scheme 'kahan-li-7'", "did you mean"]),
    (["check", "--states", "0"], ["--states", "positive integer"]),
    (["check", "--m0", "0,0,0"], ["--m0", "non-zero"]),
    (["schemes", "--bogus"], ["unrecognized arguments", "--bogus"]),
    (["sweep", "--ratios", "1"], ["--ratios", "pair"]),
    (["sweep", "--ratios", "1,3"], ["--ratios 1,3", "triangle", "--allow-nonphysical"]),
    (["sweep", "--sampling", "random"], ["--samples"]),
    (["sweep", "--dt", "0.1,-1"], ["--dt", "positive"]),
    (["sweep", "--dt-range", "0.5,0.1"], ["--dt-range", "LOW,HIGH"]),
    (["sweep", "--reference-angle", "2"], ["--reference-angle", "0.5"]),
    (["sweep", "--scheme", "blanes-moan-s10-prk", "--split", "axes"], ["blanes-moan-s10-prk", "--split casimir"]),
    (["sweep", "--resume"], ["--resume", "--out"]),
]


def _assert_one_line_error(rc, captured, words):
    assert rc == 2
    err = captured.err
    assert captured.out == ""
    assert "Traceback" not in err
    assert err.endswith("\n") and err.count("\n") == 1, f"not one line: {err!r}"
    assert err.startswith("jaxsplit: error: ")
    for word in words:
        assert word in err, f"{word!r} missing from {err!r}"


@pytest.mark.parametrize("argv,words", SIMULATE, ids=[" ".join(a) for a, _ in SIMULATE])
def test_simulate_bad_input(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(["simulate", *argv])
    _assert_one_line_error(rc, capsys.readouterr(), words)
    assert list(tmp_path.iterdir()) == []  # nothing written, nothing run


@pytest.mark.parametrize("argv,words", OTHERS, ids=[" ".join(a) for a, _ in OTHERS])
def test_other_commands_bad_input(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(argv)
    _assert_one_line_error(rc, capsys.readouterr(), words)
    assert list(tmp_path.iterdir()) == []


def test_existing_output_is_not_overwritten_without_force(capsys, tmp_path):
    out = tmp_path / "run.npz"
    out.write_bytes(b"precious")
    rc = main(["simulate", "--steps", "5", "--out", str(out)])
    _assert_one_line_error(rc, capsys.readouterr(), [str(out), "exists", "--force"])
    assert out.read_bytes() == b"precious"
    figure = tmp_path / "fig.png"
    figure.write_bytes(b"precious")
    rc = main(["simulate", "--steps", "5", "--out", str(tmp_path / "b.npz"), "--figure", str(figure)])
    _assert_one_line_error(rc, capsys.readouterr(), [str(figure), "exists", "--force"])
    assert figure.read_bytes() == b"precious" and not (tmp_path / "b.npz").exists()


def test_existing_sweep_directory_needs_resume_or_force(capsys, tmp_path):
    (tmp_path / "manifest.json").write_text("{}")
    rc = main(["sweep", "--out", str(tmp_path)])
    _assert_one_line_error(rc, capsys.readouterr(), ["already holds a sweep", "--resume", "--force"])
    rc = main(["sweep", "--out", str(tmp_path), "--resume"])
    _assert_one_line_error(rc, capsys.readouterr(), ["manifest", "cannot resume"])


def test_output_path_is_a_directory(capsys, tmp_path):
    for out in (str(tmp_path), str(tmp_path) + "/"):
        rc = main(["simulate", "--steps", "5", "--out", out])
        _assert_one_line_error(rc, capsys.readouterr(), ["is a directory", "run.npz"])
    assert list(tmp_path.iterdir()) == [] and not tmp_path.with_suffix(".npz").exists()


@pytest.mark.parametrize("module,argv,words", [
    ("jaxsplit.cli", ["simulate", "--inertia", "1,1,3"], ["not a physical body"]),
    ("jaxsplit", ["simulate", "--scheme", "stang", "--json"], ["did you mean", "strang"]),  # python -m jaxsplit
])
def test_no_traceback_through_the_real_entry_point(module, argv, words):
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.run([sys.executable, "-m", module, *argv], capture_output=True, text=True,
                          env=env, timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    for word in words:
        assert word in lines[0]


def _write_malformed(tmp_path):
    import numpy as np

    (tmp_path / "garbage.npz").write_text("not a zip file")
    np.savez(tmp_path / "no_m.npz", t=np.arange(3.0))
    np.savez(tmp_path / "nan.npz", t=np.arange(10.0), m=np.full((10, 3), np.nan))


@pytest.mark.parametrize("name,words", [("garbage.npz", ["garbage.npz"]), ("no_m.npz", ["no_m.npz", "m"]),
                                        ("nan.npz", ["finite"]), ("missing.npz", ["missing.npz"])])
def test_fit_rejects_malformed_data_files(name, words, capsys, tmp_path):
    pytest.importorskip("jaxsplit.cli.fit")  # owned by the fitting work; skipped until it exists
    _write_malformed(tmp_path)
    rc = main(["fit", "--data", str(tmp_path / name)])
    _assert_one_line_error(rc, capsys.readouterr(), words)
