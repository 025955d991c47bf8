"""``check`` chooses its ladder per scheme and says when an order is not measurable (issue
13, acceptance 2); ``sweep`` writes its figure and its tables by swept parameter. The full
acceptance run (every scheme, three bodies) is ``benchmarks/check_all_schemes.py`` (results
in ``benchmarks/results/check_all_schemes.md``): too long for the suite."""

import json

import numpy as np
import pytest

from jaxsplit.cli import main
from jaxsplit.cli.check import MIN_FIT_POINTS, ORDER_TOL, Window, _fit, _window_counts, verdict

EPS = np.finfo(np.float64).eps


def _json(capsys):
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1, lines
    return json.loads(lines[0])


def _measured(errors_of_h):
    counts = np.unique(np.round(np.geomspace(4, 4000, 80)).astype(int))  # down to round-off for every case
    hs = 10.0 / counts
    errs = errors_of_h(hs) + 20 * EPS * np.sqrt(counts)  # the round-off floor seen at T = 10
    order, before, used = _fit(counts, hs, errs, Window(1.0, EPS, 0.0))
    return {"order": order, "order_before": before, "used": used, "exact": False, "note": None}


@pytest.mark.parametrize("errors,nominal,expected", [
    (lambda h: 1e-6 * h**6, 6, "agrees"),  # asymptotic above round-off
    (lambda h: 1e-6 * h**5, 6, "disagrees"),  # a settled slope one order low: a failure
    (lambda h: 1e-9 * h**12, 10, "not measurable"),  # settles above the nominal order: its term never shows
    (lambda h: 1e-6 * h**6 + 1e-5 * h**9, 6, "agrees"),  # pre-asymptotic at large h only
    # the local slope 6 + 8 * 0.02 / (h + 0.02) is still rising where the errors reach round-off
    (lambda h: 1e-4 * h**6 * (h / (h + 0.02)) ** 8, 6, "not measurable"),
], ids=["asymptotic", "order-low", "higher", "pre-asymptotic", "unsettled"])
def test_order_verdicts(errors, nominal, expected):
    m = _measured(errors)
    state, reason = verdict(m, nominal)
    assert state == expected, (m["order"], m["order_before"])
    assert (reason is None) == (state in ("agrees", "disagrees"))
    if state == "agrees":
        assert abs(m["order"] - nominal) <= ORDER_TOL


def test_too_few_step_counts_in_the_window_is_not_an_order():
    """A high order reaches round-off within a few small step counts (kahan-li-10 at h = 2.5 .. 1.4):
    fewer than MIN_FIT_POINTS counts in the window give no order; one more count gives one."""
    counts = np.array([1, 2, 5, 6, 7, 8, 16, 32])
    hs = 10.0 / counts
    errs = 1e-12 * hs**10 + 20 * EPS * np.sqrt(counts)
    window = Window(1.0, EPS, 0.0)
    inside = _window_counts(counts, hs, errs, window)
    assert inside.size == MIN_FIT_POINTS - 1 and _fit(counts, hs, errs, window) is None
    denser = np.sort(np.append(counts, 4))  # a fifth count in the window: measured
    hs = 10.0 / denser
    order, _, used = _fit(denser, hs, 1e-12 * hs**10 + 20 * EPS * np.sqrt(denser), window)
    assert used.sum() == MIN_FIT_POINTS and abs(order - 10) <= ORDER_TOL


@pytest.mark.parametrize("scheme,split,order_state", [
    ("sofroniou-spaletta-10", "axes", "agrees"),  # exited 1 before (measured 10.322) with the fixed ladder
    ("blanes-moan-s6-prk", "casimir", "exact"),  # two pieces: the Casimir split, exact on a symmetric body
])
def test_check_with_default_settings_exits_0(scheme, split, order_state, capsys):
    assert main(["check", "--scheme", scheme, "--json", "--states", "4"]) == 0
    r = _json(capsys)
    assert r["split"] == split and r["order_verdict"] == order_state and r["poisson_ok"]
    if order_state == "agrees":
        assert abs(r["measured_order"] - r["nominal_order"]) <= ORDER_TOL
        counts = np.asarray(r["step_counts"])[np.asarray(r["used"])]
        errors = np.asarray(r["errors"])[np.asarray(r["used"])]
        assert np.all(errors > 100 * EPS * np.sqrt(counts))  # every point used lies above round-off


@pytest.mark.parametrize("argv,reference", [
    # one worker with test_cli_systems' attitude run: the attitude's exact solution (64 padded rows) compiles once
    pytest.param(["--system", "attitude", "--inertia", "3,2,1.5", "--q0", "0.6,0.8,0,0"], "exact (Jacobi elliptic)",
                 marks=pytest.mark.xdist_group("attitude-exact-solution")),
    (["--system", "heavy-top", "--inertia", "2,1.5,1", "--center-of-mass", "0.1,0,0.5"], "kahan-li-8"),
], ids=["attitude", "heavy-top"])
def test_check_other_systems(argv, reference, capsys):
    assert main(["check", "--scheme", "strang", "--json", "--states", "4", *argv]) == 0
    r = _json(capsys)
    assert r["reference"].startswith(reference) and r["poisson_ok"] and r["order_verdict"] == "agrees"
    assert abs(r["measured_order"] - 2) <= ORDER_TOL


# ---------------------------------------------------------------- sweep: figure and tables
def test_sweep_writes_a_figure_and_tables_by_each_swept_parameter(tmp_path, capsys):
    import matplotlib.image

    out = tmp_path / "sw"
    argv = ["sweep", "--scheme", "strang", "--reference-scheme", "strang", "--states", "3", "--ratios", "1,0.5",
            "0.8,0.6", "--dt", "0.2,0.1", "--t-end", "1", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "by inertia ratios" in text and "by step size" in text and "I2/I1=0.8, I3/I1=0.6" in text
    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "results.npz") as z:
        error, h_index, ratio_index = z["error"], z["case_h_index"], z["case_ratio_index"]
    by_h = summary["groups"]["step size"]
    assert [row["group"] for row in by_h] == ["h=0.2", "h=0.1"] and [row["cases"] for row in by_h] == [6, 6]
    for k, row in enumerate(by_h):
        assert row["error_median"] == pytest.approx(np.median(error[h_index == k]), rel=1e-12)
        assert row["error_max"] == pytest.approx(np.max(error[h_index == k]), rel=1e-12)
    assert by_h[0]["error_median"] > 3 * by_h[1]["error_median"]  # second order: halving h quarters the error
    by_ratio = summary["groups"]["inertia ratios"]
    assert [row["cases"] for row in by_ratio] == [6, 6]
    assert by_ratio[1]["error_max"] == pytest.approx(np.max(error[ratio_index == 1]), rel=1e-12)
    image = matplotlib.image.imread(out / "sweep.png")
    assert image.shape[1] >= 1200 and np.mean(np.any(image[..., :3] < 0.9, axis=-1)) > 0.03
    assert summary["figure"] == str(out / "sweep.png")
