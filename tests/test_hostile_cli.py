"""The command line against a hostile user (issue 10), in-process through ``main``.

Grouped by the classes of the issue; each case asserts the exact contract:

* bad input, unbounded work, misleading messages: exit 2, ONE line on stderr naming the
  value (and what is allowed), nothing on stdout, no traceback, nothing written;
* work lost or overwritten: outputs are one file however they are spelled, never
  replaced without --force, never shared by two runs (a held lock means exit 2), and a
  resumed sweep reuses only chunks that prove their inputs;
* silent wrong results: degenerate data are refused, extreme but valid inputs give the
  right answer.

Signals and real concurrent processes are in ``test_signals.py``.
"""

import json
import os
import stat

import numpy as np
import pytest

from jaxsplit.cli import main
from jaxsplit.cli._io import Outputs

LONG_NAME = "r" * 300 + ".npz"


def _assert_refused(rc, captured, words):
    assert rc == 2, captured
    err = captured.err
    assert captured.out == "" and "Traceback" not in err
    assert err.startswith("jaxsplit: error: ") and err.count("\n") == 1, f"not one line: {err!r}"
    for word in words:
        assert word in err, f"{word!r} missing from {err!r}"


def _refused(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main(argv)
    _assert_refused(rc, capsys.readouterr(), words)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written, nothing left behind


# ---------------------------------------------------------------- 3, 4: bad input, bounds, messages
SIMULATE = [
    (["--dt", "1e-300", "--t-end", "1"], ["--t-end 1", "--dt 1e-300", "1e+300 steps", "more than"]),
    (["--t-end", "1e300", "--dt", "1e-300"], ["inf steps", "larger --dt"]),
    (["--t-end", "1e308"], ["--t-end 1e+308", "steps", "more than"]),
    (["--t-end", "1e-5"], ["--t-end 1e-05", "shorter than one step"]),
    (["--steps", "1e30"], ["--steps is 1,000,000,000,000,000,019,884,624,838,656", "more than"]),
    (["--steps", "1e400"], ["--steps", "positive integer", "'1e400'"]),
    (["--steps", "-1e3"], ["--steps", "positive integer"]),
    (["--steps", "0x10"], ["--steps", "positive integer", "'0x10'"]),
    (["--steps", ""], ["--steps", "positive integer"]),
    (["--save-every", "1e30", "--steps", "10"], ["--save-every", "more than"]),
    (["--inertia", "1e-320,1,1"], ["--inertia", "1/I1 overflows", "at least"]),
    (["--inertia", "1,1e-310,1", "--allow-nonphysical"], ["--inertia", "1/I2 overflows"]),
    (["--m0", "1e150,0,0", "--inertia", "1e-160,1,1", "--allow-nonphysical"], ["--m0", "--inertia", "energy"]),
    (["--m0", "1e200,0,0"], ["--m0", "|m0|^2 overflows"]),
    (["--m0", "-inf,0,0.8"], ["--m0", "finite", "'-inf,0,0.8'"]),
    (["--m0", "-nan,0,0.8"], ["--m0", "finite"]),
    (["--m0", "2,,1"], ["--m0", "'2,,1'", "value 2 is empty"]),
    (["--m0", ",,"], ["--m0", "value 1 is empty"]),
    (["--m0", "1,2,3,"], ["--m0", "got 4 values"]),
    (["--inertia", "1;2;3"], ["--inertia", "got 1 value"]),
    (["--dt", "-inf"], ["--dt", "finite non-zero", "'-inf'"]),
    (["--dt", "1e400"], ["--dt", "finite non-zero"]),
    (["--t-end", "-1"], ["--t-end", "positive"]),
    (["--t-end", "nan"], ["--t-end", "positive"]),
    (["--max-memory", "0.1"], ["--max-memory", "at least 1 byte", "'0.1'"]),
    (["--max-memory", "0"], ["--max-memory", "at least 1 byte"]),
    (["--max-memory", "1e400"], ["--max-memory", "at least 1 byte"]),
    (["--max-memory", "-5G"], ["--max-memory", "500M or 2G"]),
    (["--max-memory", "1", "--steps", "10"], ["--max-memory", "save fewer states"]),
    (["--scheme", "triple-jump-1000000"], ["triple-jump-1000000", "stages", "triple-jump-14 is the largest"]),
    (["--scheme", "triple-jump-16"], ["triple-jump-16 has 3^7 stages", "1,000"]),
    (["--scheme", "triple-jump-" + "9" * 5000], ["3^((N-2)/2) stages"]),
    (["--scheme", "triple-jump-7"], ["triple-jump order must be an even integer"]),
    (["--scheme", ""], ["unknown scheme ''"]),
    (["--split", "casimir", "--shift-axis", "4"], ["--shift-axis", "invalid choice", "'4'"]),
    (["--format", "json"], ["--format", "invalid choice"]),
    (["--out", LONG_NAME], ["--out", "304 bytes long", "allows 255"]),
    (["--steps", "5", "--out", "a.npz", "--figure", LONG_NAME.replace("npz", "png")], ["figure", "304 bytes long"]),
    (["--out", "x.npz", "--figure", "x.npz"], ["figure 'x.npz' is the same file as the trajectory"]),
    (["--out", "x.npz", "--figure", "./x.npz"], ["same file as the trajectory"]),
    (["--out", "x.csv", "--figure", f"{'sub'}/../x.csv"], ["same file as the trajectory"]),
    (["--out", "new-dir/"], ["--out 'new-dir/' is a directory"]),
    (["--figure", "no-such-dir/f.png"], ["no-such-dir", "does not exist"]),
]

SWEEP = [
    (["--sampling", "random", "--samples", "3", "--seed", "-1"], ["--seed", "'-1'", "integer >= 0"]),
    (["--sampling", "random", "--samples", "3", "--seed", str(2**64)], ["--seed", "below 2^64"]),
    (["--sampling", "random", "--samples", "3", "--seed", "1.5"], ["--seed", "'1.5'"]),
    (["--states", "1e12"], ["1,000,000,000,000 cases", "--max-memory", "at most"]),
    (["--sampling", "random", "--samples", "1e12"], ["1,000,000,000,000 cases", "--max-memory"]),
    (["--states", "100", "--max-memory", "1K"], ["100 cases", "1.0 KiB", "--max-memory"]),
    (["--t-end", "1e300"], ["--t-end 1e+300", "--dt 0.1", "more than the 2,147,483,647", "int32"]),
    (["--dt", "1e-12", "--t-end", "10"], ["--dt 1e-12", "1e+13 steps", "int32"]),
    (["--sampling", "random", "--samples", "2", "--dt-range", "1e-12,1e-11"], ["--dt-range (low end)", "int32"]),
    (["--t-end", "1e9", "--dt", "1", "--states", "1"], ["reference would need", "steps"]),
    (["--ratios", "1e-320,1"], ["--ratios", "finite inverses"]),
    (["--ratios", "1,1,1"], ["--ratios", "pair"]),
    (["--ratios", "-1,1"], ["--ratios", "positive", "'-1,1'"]),
    (["--reference-scheme", "triple-jump-100"], ["--reference-scheme triple-jump-100", "stages"]),
    (["--reference-scheme", "nope"], ["unknown scheme 'nope'"]),
    (["--scheme", "triple-jump-22"], ["--scheme triple-jump-22", "3^10 stages"]),
    (["--chunk-cases", "0"], ["--chunk-cases", "positive integer"]),
    (["--reference-angle", "0"], ["--reference-angle", "positive"]),
    (["--samples", "3"], ["--samples has no effect here", "only with --sampling random"]),
    # a flag without effect in its combination is refused, never ignored (one check: _args.refuse_unused)
    (["--ratio-range", "0.5,2"], ["--ratio-range has no effect here", "--sampling random"]),
    (["--dt-range", "0.01,0.1"], ["--dt-range has no effect here", "--sampling random"]),
    (["--seed", "3"], ["--seed has no effect here", "--sampling random"]),
    (["--sampling", "random", "--samples", "3", "--states", "4"], ["--states has no effect here", "--sampling grid"]),
    (["--sampling", "random", "--samples", "3", "--dt", "0.1"], ["--dt has no effect here", "--sampling grid"]),
    (["--split", "axes", "--shift-axis", "2"], ["--shift-axis has no effect here", "--split casimir"]),
    (["--resume", "--out", "nothere"], ["nothing to resume", "'nothere' does not exist"]),
    (["--resume", "--out", "sub"], ["nothing to resume", "'sub' holds no sweep"]),
    (["--out", "mine"], ["--out 'mine' is not empty", "'notes.txt'", "--force"]),
    (["--max-memory", "1"], ["--max-memory", "cases"]),
    (["--resume", "--force", "--out", "d"], ["--resume and --force contradict"]),
    (["--out", "a-file"], ["--out directory 'a-file' exists and is not a directory"]),
    (["--out", "d" * 300], ["--out directory", "300 bytes long"]),
]

CHECK = [
    (["--start", "1e9"], ["--start is 1,000,000,000", "8,192", "16 x --start"]),
    (["--start", "8193"], ["--start is 8,193"]),
    (["--states", "1e12"], ["--states is 1,000,000,000,000", "100,000"]),
    (["--t-end", "1e-300"], ["turns by only", "--t-end 1e-300", "0.1 rad"]),
    (["--t-end", "0.001"], ["turns by only 0.00024 rad"]),
    (["--m0", "1e-300,1e-300,0"], ["no order can be measured", "0.1 rad"]),
    (["--m0", "0,0,1"], ["--m0 is an equilibrium"]),
    (["--inertia", "1,1,1", "--m0", "0.6,0,0.8"], ["--m0 is an equilibrium"]),
    (["--seed", "-1"], ["--seed", "'-1'"]),
    (["--scheme", "triple-jump-20"], ["triple-jump-20", "stages"]),
    (["--inertia", "1e-320,1,1"], ["1/I1 overflows"]),
    (["--dt", "-inf"], ["--dt", "finite non-zero"]),
    (["--m0", "1e200,1e200,0"], ["--m0", "overflows"]),
    (["--split", "axes", "--shift-axis", "2"], ["--shift-axis applies only with a shifted split", "--split casimir"]),
]

PAPER = [
    (["--out", "a", "--claims", ","], ["--claims", "names no claims", "','"]),
    (["--out", "a", "--claims", " , "], ["--claims", "names no claims"]),
    (["--out", "a", "--claims", "nope"], ["unknown claim id(s) ['nope']"]),
    (["--out", "a-file"], ["--out directory 'a-file' exists and is not a directory"]),
    (["--out", "p" * 300], ["--out directory", "300 bytes long"]),
    (["--out", "old", "--claims", "stages"], ["--out 'old' already holds an audit", "--resume", "--force"]),
    (["--out", "nothere", "--resume"], ["nothing to resume", "'nothere' does not exist"]),
    (["--out", "sub", "--resume"], ["nothing to resume", "holds no claims.json"]),
    (["--out", "old", "--resume", "--force"], ["--resume and --force contradict"]),
    (["--out", "old", "--resume"], ["cannot resume", "claims.json", "is not a jaxsplit audit"]),
    (["--out", "old", "--resume", "--claims", "stages"], ["--claims has no effect here", "without --resume"]),
    (["--out", "old-report", "--claims", "stages"], ["report.md", "exists", "--force"]),
    (["--out", "old-figure", "--claims", "order2"], ["order2_ladder.png", "exists", "--force"]),
]


# Systems, --save-at, --noise, --dtype, --reference (issues 9, 11, 13): the same contract.
SYSTEMS = [
    (["--system", "heavy-top", "--gamma0", "0,0,2"], ["--gamma0 0,0,2 has norm 2", "unit vector", "0,0,1"]),
    (["--system", "gravity-gradient", "--gamma0", "0,0,0"], ["--gamma0 0,0,0 has norm 0", "unit vector"]),
    (["--system", "heavy-top", "--gamma0", "0.577,0.577,0.577"], ["norm 0.999393", "0.57735026918962"]),
    (["--system", "gravity-gradient", "--rate", "-1"], ["--rate", ">= 0", "'-1'"]),
    (["--system", "gravity-gradient", "--rate", "inf"], ["--rate", ">= 0"]),
    (["--system", "heavy-top", "--weight", "-0.5"], ["--weight", ">= 0", "'-0.5'"]),
    (["--system", "heavy-top", "--weight", "nan"], ["--weight", ">= 0"]),
    (["--weight", "1"], ["--weight applies only to --system heavy-top", "this is --system rigid-body"]),
    (["--system", "attitude", "--gamma0", "0,0,1"], ["--gamma0 applies only to --system heavy-top or gravity-gradient"]),
    (["--system", "heavy-top", "--rate", "1"], ["--rate applies only to --system gravity-gradient"]),
    (["--system", "attitude", "--q0", "1,1,0,0"], ["--q0 1,1,0,0 has norm 1.41421356", "unit quaternion"]),
    (["--system", "attitude", "--q0", "1,0,0"], ["--q0", "4 comma-separated", "got 3 values"]),
    (["--system", "heavy-top", "--inertia", "1,1,3"], ["not a physical body", "--allow-nonphysical"]),
    (["--system", "heavy-top", "--center-of-mass", "1e308,1e308,0", "--weight", "1e10", "--gamma0", "1,0,0"],
     ["--system heavy-top", "energy", "overflows"]),
    (["--system", "heavy-top", "--center-of-mass", "nan,0,0"], ["--center-of-mass", "finite"]),
    (["--system", "spinning-top"], ["--system", "invalid choice", "'spinning-top'"]),
    (["--system", "attitude", "--split", "casimir"], ["--split casimir is not offered by --system attitude",
                                                      "spin", "offered: axes, spin"]),
    (["--system", "heavy-top", "--inertia", "2,1.5,1", "--split", "symmetric"], ["--split symmetric", "I1 = I2"]),
    (["--system", "heavy-top", "--inertia", "2,1.5,1", "--scheme", "blanes-moan-s6-prk"],
     ["blanes-moan-s6-prk", "any split of --system heavy-top", "axes: 4 pieces"]),
    (["--system", "gravity-gradient", "--reference", "exact"], ["--reference exact", "free body", "has none"]),
    (["--system", "attitude", "--split", "axes", "--shift-axis", "1"], ["--shift-axis applies only", "spin"]),
    (["--save-at", "5", "--steps", "10"], ["--save-at 5 is after the end of the run", "t = 0.1", "--t-end"]),
    (["--save-at", "-1"], ["--save-at -1 is before the start of the run"]),
    (["--save-at", "1", "--dt", "-0.01"], ["--save-at 1 is before the start", "backwards: times must be <= 0"]),
    (["--save-at", ","], ["--save-at", "names no times"]),
    (["--save-at", "1,,2"], ["--save-at", "value 2", "is empty"]),
    (["--save-at", "nan"], ["--save-at", "must be finite"]),
    (["--save-at", "1,abc"], ["--save-at", "'abc' is not a number"]),
    (["--save-at", "@missing.txt"], ["--save-at", "no such file 'missing.txt'"]),
    (["--save-at", "@sub"], ["--save-at", "'sub' is not a regular file"]),
    (["--save-at", "@/dev/zero"], ["--save-at", "'/dev/zero' is not a regular file"]),
    (["--save-at", "@"], ["--save-at", "@ must be followed by a file name"]),
    (["--save-at", "@bad-times.txt"], ["--save-at", "line 3 of 'bad-times.txt'", "'2,5' is not a number"]),
    (["--save-at", "@empty-times.txt"], ["--save-at", "holds no times"]),
    (["--save-at", "1e300"], ["--save-at 1e+300 / --dt 0.01", "steps, more than"]),
    (["--save-at", "1,2", "--max-memory", "3K"], ["--max-memory", "saved states"]),
    (["--noise", "1e-3", "--no-save"], ["--noise has no effect here", "the written trajectory", "--no-save"]),
    (["--seed", "3"], ["--seed has no effect here", "--noise SIGMA > 0"]),
    (["--out", "x.npz", "--figure", "x.png", "--no-figure"], ["--figure has no effect here", "without --no-figure"]),
    (["--no-save", "--format", "csv"], ["--format has no effect here", "--no-save"]),
    (["--no-save", "--force"], ["--force has no effect here", "--no-save"]),
    (["--no-save", "--no-figure"], ["--no-figure has no effect here", "--no-save"]),
    (["--noise", "-1"], ["--noise", ">= 0"]),
    (["--seed", "-3"], ["--seed", "'-3'"]),
    (["--dtype", "float16"], ["--dtype", "invalid choice", "'float16'"]),
    (["--reference", "elliptic"], ["--reference", "invalid choice"]),
    (["--tol", "1e-8", "--scheme", "strang", "--dt", "0.1"], ["--tol chooses the scheme", "drop --scheme, --dt"]),
    (["--tol", "0"], ["--tol", "positive"]),
]
CHECK_SYSTEMS = [
    (["--system", "heavy-top", "--reference", "exact"], ["--reference exact", "use --reference numerical"]),
    (["--system", "heavy-top", "--gamma0", "0,0,3"], ["--gamma0 0,0,3 has norm 3"]),
    (["--system", "heavy-top", "--m0", "0,0,1", "--gamma0", "0,0,1", "--center-of-mass", "0,0,1"],
     ["equilibrium of --system heavy-top", "no order can be measured"]),
    (["--system", "attitude", "--split", "symmetric"], ["--split symmetric is not offered by --system attitude"]),
]
SWEEP_SYSTEMS = [
    (["--system", "heavy-top"], ["--system heavy-top", "free-body cases", "jaxsplit.sweep"]),
]


def _setup(tmp_path):
    (tmp_path / "a-file").write_text("x")
    (tmp_path / "bad-times.txt").write_text("0.5\n# a comment\n2,5\n")
    (tmp_path / "empty-times.txt").write_text("# nothing\n\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("the user's")
    for name, file in (("old", "claims.json"), ("old-report", "report.md"), ("old-figure", "order2_ladder.png")):
        (tmp_path / name).mkdir()
        (tmp_path / name / file).write_text("precious")


_TABLES = (("simulate", SIMULATE), ("sweep", SWEEP), ("check", CHECK), ("paper", PAPER), ("simulate", SYSTEMS),
           ("check", CHECK_SYSTEMS), ("sweep", SWEEP_SYSTEMS))


@pytest.mark.parametrize("command,argv,words", [(c, a, w) for c, table in _TABLES for a, w in table],
                         ids=[f"{c}: {' '.join(a)[:60]}" for c, table in _TABLES for a, _ in table])
def test_refused_with_one_line_naming_the_value(command, argv, words, capsys, tmp_path, monkeypatch):
    _setup(tmp_path)
    _refused([command, *argv], words, capsys, tmp_path, monkeypatch)
    for name in ("old", "old-report", "old-figure"):  # an earlier audit is untouched
        assert [p.read_text() for p in (tmp_path / name).iterdir()] == ["precious"]


# ---------------------------------------------------------------- fit: malformed and degenerate data
def _obs(t, m, **extra):
    return {"t": np.asarray(t), "m": np.asarray(m), **extra}


_T = np.linspace(0.0, 1.0, 10)
_MOVING = np.stack([np.cos(_T), np.sin(_T), 0.5 + 0 * _T], axis=1)
FIT_FILES = {
    "npy": (lambda p: np.save(p, _MOVING), ["single array (.npy)", ".npz"]),
    "complex": (lambda p: np.savez(p, **_obs(_T, _MOVING * (1 + 1j))), ["m must be real", "complex"]),
    "zero": (lambda p: np.savez(p, **_obs(_T, 0 * _MOVING)), ["do not determine the inertia", "zero"]),
    "on-axis": (lambda p: np.savez(p, **_obs(_T, np.tile([0.0, 0.0, 2.0], (10, 1)))), ["principal axis"]),
    "decreasing": (lambda p: np.savez(p, **_obs(_T[::-1], _MOVING)), ["strictly increasing"]),
    "three": (lambda p: np.savez(p, **_obs(_T[:3], _MOVING[:3])), ["3 observation times", "at least 4",
                                                                     "--save-at"]),
    "gamma-zero": (lambda p: np.savez(p, **_obs(_T, _MOVING, gamma=0 * _MOVING)),
                   ["do not determine", "weight x centre of mass x", "gamma is 0 at every observation"]),
    "inf": (lambda p: np.savez(p, **_obs(_T, np.where(_MOVING > 0.9, np.inf, _MOVING))), ["m must be finite"]),
    "object": (lambda p: np.savez(p, t=_T, m=np.array([object()] * 30).reshape(10, 3)), ["not a readable .npz"]),
    "energy-pair": (lambda p: np.savez(p, **_obs(_T, _MOVING, energy=np.ones(2))), ["'energy'", "one number"]),
    "truncated": (lambda p: (np.savez(p, **_obs(_T, _MOVING)), p.write_bytes(p.read_bytes()[:100])),
                  ["not a readable .npz"]),
    "directory": (lambda p: p.mkdir(), ["not a readable .npz"]),
}
FIT_OPTIONS = [
    (["--energy", "-1"], ["--energy", "positive"]),
    (["--energy", "nan"], ["--energy", "positive"]),
    (["--energy-sigma", "-1"], ["--energy-sigma", ">= 0"]),
    (["--energy-sigma", "0.1"], ["--energy-sigma has no effect here", "with an energy gauge"]),
    (["--inertia1", "2", "--energy-sigma", "0.1"], ["--energy-sigma has no effect here"]),
    (["--inertia1", "0"], ["--inertia1", "positive"]),
    (["--max-step", "0"], ["--max-step", "positive"]),
    (["--max-step", "1e-300"], ["max_step 1e-300", "more than 2,147,483,647"]),
    (["--max-step", "1e-6"], ["model's steps per evaluation", "1,000,000", "--max-step"]),
    (["--scheme", "triple-jump-1000000"], ["triple-jump-1000000", "stages"]),
    (["--scheme", "nope"], ["unknown scheme 'nope'"]),
    (["--energy", "1", "--inertia1", "2"], ["one gauge"]),
    (["--weight", "2"], ["--weight applies to a heavy-top fit"]),
    (["--weight", "0"], ["--weight", "positive"]),
    (["--system", "heavy-top"], ["--system heavy-top needs gamma (n, 3)"]),
    (["--system", "attitude"], ["--system", "invalid choice"]),
]
# The one data format read back: a CSV is parsed line by line, each fault named with its line.
_HEADER = "# metadata: {}\n# t,m1,m2,m3\n"
_ROWS = "".join(f"{t:.3f},{a:.6f},{b:.6f},{c:.6f}\n" for t, (a, b, c) in zip(_T, _MOVING))
FIT_CSV = {
    "no-header": ("0,1,2,3\n", ["line 1 must name the columns", "'0,1,2,3'"]),
    "empty": ("", ["holds no column names"]),
    "metadata-only": ("# metadata: {}\n", ["holds no column names"]),
    "bad-metadata": ("# metadata: {oops\n# t,m1,m2,m3\n" + _ROWS, ["line 1 is not '# metadata: <JSON object>'"]),
    "short-row": (_HEADER + _ROWS + "1.5,0.1,0.2\n", ["line 13 has 3 values", "names 4 columns"]),
    "not-a-number": (_HEADER + _ROWS.replace("0.500000", "half", 1), ["line 3", "'half' is not a number"]),
    "duplicate-column": ("t,m1,m1,m3\n" + _ROWS, ["distinct names"]),
    "no-m": ("t,x1,x2,x3\n" + _ROWS, ["missing array(s) ['m']"]),
    "nan": (_HEADER + _ROWS.replace("0.500000", "nan", 1), ["m must be finite", "1 NaN/inf"]),
    "gamma-partial": ("t,m1,m2,m3,gamma1,gamma2\n" + "".join(r.strip() + ",0,1\n" for r in _ROWS.splitlines()),
                      ["--system heavy-top needs gamma (n, 3)"]),
    "binary": (b"\x00\xff\xfe garbage", ["not a readable .csv file", "UnicodeDecodeError"]),
    "satellite": ('# metadata: {"system": "gravity-gradient"}\n# t,m1,m2,m3,gamma1,gamma2,gamma3\n'
                  + "".join(r.strip() + ",0,0,1\n" for r in _ROWS.splitlines()),
                  ["holds a gravity-gradient run", "--system rigid-body"]),
}


@pytest.mark.parametrize("name", list(FIT_CSV))
def test_fit_refuses_malformed_csv(name, capsys, tmp_path, monkeypatch):
    content, words = FIT_CSV[name]
    path = tmp_path / f"{name}.csv"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    extra = ["--system", "heavy-top"] if name == "gamma-partial" else []
    _refused(["fit", "--data", str(path), *extra], words, capsys, tmp_path, monkeypatch)


def test_fit_refuses_a_fifo_before_opening_it(capsys, tmp_path, monkeypatch):
    os.mkfifo(tmp_path / "obs.csv")  # opening it would block until a writer came
    _refused(["fit", "--data", "obs.csv"], ["obs.csv is not a readable .csv file", "not a regular file"], capsys,
             tmp_path, monkeypatch)


@pytest.mark.parametrize("name", list(FIT_FILES))
def test_fit_refuses_malformed_and_degenerate_data(name, capsys, tmp_path, monkeypatch):
    path = tmp_path / (f"{name}.npy" if name == "npy" else f"{name}.npz")
    make, words = FIT_FILES[name]
    make(path)
    _refused(["fit", "--data", str(path)], words, capsys, tmp_path, monkeypatch)


@pytest.mark.parametrize("argv,words", FIT_OPTIONS, ids=[" ".join(a) for a, _ in FIT_OPTIONS])
def test_fit_refuses_bad_options(argv, words, capsys, tmp_path, monkeypatch):
    np.savez(tmp_path / "obs.npz", **_obs(_T, _MOVING))
    _refused(["fit", "--data", "obs.npz", *argv], words, capsys, tmp_path, monkeypatch)


# ---------------------------------------------------------------- 1: work lost or overwritten
def test_a_symlink_or_hard_link_to_an_output_is_that_output(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "target.npz").write_bytes(b"precious")
    os.symlink("target.npz", tmp_path / "link.npz")
    rc = main(["simulate", "--steps", "5", "--out", "link.npz", "--no-figure"])
    _assert_refused(rc, capsys.readouterr(), ["'link.npz' exists", "--force"])
    os.link(tmp_path / "target.npz", tmp_path / "hard.png")
    rc = main(["simulate", "--steps", "5", "--out", "target.npz", "--figure", "hard.png", "--force"])
    _assert_refused(rc, capsys.readouterr(), ["figure 'hard.png' is the same file as the trajectory"])



@pytest.mark.parametrize("command", ["simulate", "sweep", "paper"])
def test_force_replaces_a_symlink_never_the_file_it_points_to(command, capsys, tmp_path, monkeypatch):
    """Every output goes through the one writer: --force replaces the link itself."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "other.txt").write_text("precious")
    out, argv = {"simulate": ("x.npz", ["simulate", "--steps", "5", "--no-figure", "--out", "x.npz"]),
                 "sweep": ("d/summary.json", ["sweep", "--states", "2", "--t-end", "0.2", "--no-figure", "--out", "d"]),
                 "paper": ("d/claims.json", ["paper", "--claims", "stages", "--out", "d"])}[command]
    (tmp_path / out).parent.mkdir(exist_ok=True)
    os.symlink(tmp_path / "other.txt", tmp_path / out)
    assert main([*argv, "--force", "--quiet"] if command != "paper" else [*argv, "--force"]) == 0, capsys.readouterr()
    assert (tmp_path / "other.txt").read_text() == "precious"
    assert not (tmp_path / out).is_symlink() and (tmp_path / out).stat().st_size > 0


@pytest.mark.parametrize("special", ["device", "fifo"])
def test_a_special_file_is_never_replaced_even_with_force(special, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if special == "fifo":
        os.mkfifo(tmp_path / "run.npz")
        rc = main(["simulate", "--steps", "5", "--out", "run.npz", "--no-figure", "--force"])
        _assert_refused(rc, capsys.readouterr(), ["'run.npz' exists and is not a regular file", "never replaced"])
        assert stat.S_ISFIFO(os.lstat(tmp_path / "run.npz").st_mode)
    else:  # a symlink to a device: the link is replaced, the device never written
        os.symlink("/dev/null", tmp_path / "run.npz")
        assert main(["simulate", "--steps", "5", "--out", "run.npz", "--no-figure", "--force", "--quiet"]) == 0
        assert (tmp_path / "run.npz").is_file() and not (tmp_path / "run.npz").is_symlink()
    assert os.path.exists("/dev/null") and not os.path.isfile("/dev/null")


@pytest.mark.parametrize("command", ["simulate", "sweep", "paper"])
def test_an_output_held_by_another_run_exits_2(command, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = {"simulate": ["simulate", "--steps", "5", "--out", "run.npz", "--no-figure"],
            "sweep": ["sweep", "--states", "2", "--out", "shared"],
            "paper": ["paper", "--out", "shared", "--claims", "stages"]}[command]
    with Outputs() as other:  # another jaxsplit run holding the output
        other.directory(tmp_path / "shared", "--out directory")
        other.file(tmp_path / "run.npz", "trajectory")
        rc = main(argv)
        _assert_refused(rc, capsys.readouterr(), ["in use by another jaxsplit run", f"(pid {os.getpid()})"])
    assert not (tmp_path / "run.npz").exists() and list((tmp_path / "shared").glob("*")) == []


# ---------------------------------------------------------------- 1: resume trusts only proven chunks
SMALL_SWEEP = ["sweep", "--scheme", "strang", "--reference-scheme", "strang", "--states", "8", "--chunk-cases", "4",
               "--t-end", "1", "--quiet", "--json"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "done"
    assert main(SMALL_SWEEP + ["--out", str(out)]) == 0
    with np.load(out / "results.npz") as z:
        results = {k: z[k] for k in z.files if k != "metadata"}
    return out, results


def _copy(src, dst, skip=()):
    dst.mkdir()
    for p in src.iterdir():
        if p.name not in skip:
            (dst / p.name).write_bytes(p.read_bytes())
    return dst


def _resume(out, capsys, argv=SMALL_SWEEP):
    capsys.readouterr()
    rc = main(argv + ["--out", str(out), "--resume"])
    captured = capsys.readouterr()
    return rc, captured


def _edit_chunk(path, edit):
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    edit(arrays)
    np.savez(path, **arrays)


@pytest.mark.parametrize("edit,recomputed", [
    (lambda a: a.update(energy_error=a["energy_error"][:2]), 1),  # a short array: would merge misaligned
    (lambda a: a.update(error=a["error"] * 1.5), 1),  # edited numbers
    (lambda a: a.pop("proof"), 1),  # an old-format chunk: cannot prove its inputs
    (lambda a: a.update(case_index=a["case_index"] + 4), 1),  # another chunk's range
], ids=["short-array", "edited-values", "no-proof", "wrong-range"])
def test_resume_recomputes_a_chunk_that_cannot_prove_itself(edit, recomputed, finished, tmp_path, capsys):
    out = _copy(finished[0], tmp_path / "copy", skip=("results.npz", "summary.json"))
    _edit_chunk(out / "chunk-00001.npz", edit)
    rc, captured = _resume(out, capsys)
    assert rc == 0, captured.err
    assert json.loads(captured.out)["chunks_computed"] == recomputed
    with np.load(out / "results.npz") as z:
        for key, value in finished[1].items():
            np.testing.assert_array_equal(z[key], value)


def test_resume_without_manifest_reuses_proven_chunks(finished, tmp_path, capsys):
    out = _copy(finished[0], tmp_path / "copy", skip=("manifest.json", "results.npz", "summary.json"))
    rc, captured = _resume(out, capsys)
    assert rc == 0 and json.loads(captured.out)["chunks_computed"] == 0


def test_resume_without_manifest_refuses_chunks_of_other_inputs(finished, tmp_path, capsys):
    out = _copy(finished[0], tmp_path / "copy", skip=("manifest.json",))
    other = [a if a != "strang" else "lie-trotter" for a in SMALL_SWEEP[:3]] + SMALL_SWEEP[3:]
    rc, captured = _resume(out, capsys, other)
    _assert_refused(rc, captured, ["chunk-00000.npz", "holds a chunk of a sweep with other inputs", "--force"])
    assert sorted(p.name for p in out.glob("chunk-*")) == ["chunk-00000.npz", "chunk-00001.npz"]


@pytest.mark.parametrize("manifest", ["[]", '"x"', '{"inputs": 5}', '{"inputs": [1]}', "{", "null"])
def test_resume_refuses_a_manifest_of_the_wrong_type(manifest, finished, tmp_path, capsys):
    out = _copy(finished[0], tmp_path / "copy")
    (out / "manifest.json").write_text(manifest)
    rc, captured = _resume(out, capsys)
    _assert_refused(rc, captured, ["cannot resume", "not a jaxsplit sweep manifest"])


# ---------------------------------------------------------------- 2: extreme but valid inputs, right answers
def test_a_subnormal_step_moves_nothing(capsys):
    assert main(["simulate", "--dt", "1e-320", "--steps", "5", "--no-save", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["steps"] == 5 and s["exact_error_max"] == 0.0 and s["energy_error_max"] == 0.0


def test_a_save_interval_beyond_the_run_keeps_the_first_and_last_states(capsys, tmp_path):
    out = tmp_path / "r.npz"
    assert main(["simulate", "--steps", "3", "--save-every", "1e6", "--out", str(out), "--no-figure"]) == 0
    with np.load(out) as z:
        assert list(z["step"]) == [0, 3]


def test_a_sweep_shorter_than_its_step_runs_one_exact_step(capsys, tmp_path):
    argv = [a if a != "1" else "0.05" for a in SMALL_SWEEP]  # --t-end 0.05 with the default --dt 0.1
    assert main(argv + ["--out", str(tmp_path / "s")]) == 0
    with np.load(tmp_path / "s" / "results.npz") as z:
        assert np.all(z["n_steps"] == 1) and np.all(z["h"] == 0.05)
