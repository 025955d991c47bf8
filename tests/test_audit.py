"""The paper audit: record structure, CLI behaviour, and the measurements behind the key
verdicts (each with a must-pass and a must-fail case). The full audit (all ids, < 2 min)
is run by `jaxsplit paper --out DIR`; here a cheap subset runs end to end."""

import json
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import PAPER_BODY, RigidBody, hat, poisson_defect
from jaxsplit.checks._poisson import random_unit_states
from jaxsplit.cli import main
from jaxsplit.paper._audit import CLAIM_IDS, CLAIMS
from jaxsplit.paper._records import VERDICTS, answer_from_defect, question_verdict
from jaxsplit.paper._report import cell, number
from jaxsplit.paper._section2 import iff_verdict
from jaxsplit.paper._section3 import _one_stage_step
from jaxsplit.paper._section4 import formula_4_3, formula_4_3_sequential
from jaxsplit.paper._section4_remarks import (
    _departure_scenario,
    crossover_time,
    first_departure,
    tangent_block,
)

ISSUE_IDS = ("ex2.1-i", "ex2.1-ii", "prop2.1", "prop2.2", "ex3.1-i", "ex3.1-ii", "ex3.1-iii", "ex3.1-iv",
             "prop3.1", "prop3.2", "thm4.1", "prop4.2", "order2", "order4", "order2n+2", "stages", "rem4.1",
             "rem4.2", "rem4.4", "rem4.5")
POISSON_TOL = 1e-12
PRINTED_FLOOR = 1e-4  # (4.3) as printed at h in [0.05, 0.5]: defect ~1e-3 .. 1e-1
EQUAL_TOL = 1e-14
MAX_DIGITS = 4  # significant digits of any number in report.md (3 by design; 4 leaves room for "1000")
SUBSET = ("ex2.1-i", "ex2.1-ii", "stages", "rem4.5")

BODY = RigidBody(jnp.asarray(PAPER_BODY))
STATES = random_unit_states(jax.random.PRNGKey(9), 64)
STEPS = jnp.linspace(0.05, 0.5, 64)


def test_every_issue_id_has_a_measurement():
    assert set(ISSUE_IDS) <= set(CLAIM_IDS)
    assert len(CLAIM_IDS) == len(set(CLAIM_IDS))  # each id measured by exactly one function
    assert all(callable(claim) and ids for ids, claim in CLAIMS)


def test_cli_subset_end_to_end(tmp_path):
    out = tmp_path / "audit"
    assert main(["paper", "--out", str(out), "--claims", ",".join(SUBSET)]) == 0
    records = json.loads((out / "claims.json").read_text())
    assert [r["id"] for r in records] == list(SUBSET)
    for r in records:
        assert set(r) >= {"id", "statement", "verdict", "evidence"}
        assert r["verdict"] in VERDICTS
        assert r["statement"] and "\n" not in r["statement"]
        words = json.dumps(r["evidence"]).replace(",", " ").split()
        numbers = [v for v in words if any(c.isdigit() for c in v)]
        assert numbers, r["id"]
    report = (out / "report.md").read_text()
    assert all(f"### {cid} — " in report for cid in SUBSET)
    assert (out / "rem45_orbit.png").stat().st_size > 1000
    # every figure written is embedded exactly once, under the heading of its claim
    for png in out.glob("*.png"):
        assert report.count(f"]({png.name})") == 1, png.name
    assert report.index("](rem45_orbit.png)") > report.index("### rem4.5 — ")
    # numbers for a reader: no "None", no long mantissas (full precision stays in claims.json)
    assert "None" not in report
    digits = lambda x: len(x.replace(".", "").lstrip("0"))
    long_numbers = [x for x in re.findall(r"\d+\.\d+", report) if digits(x) > MAX_DIGITS]
    assert not long_numbers
    # a second run refuses to overwrite; --force allows it
    assert main(["paper", "--out", str(out), "--claims", "stages"]) == 2
    assert main(["paper", "--out", str(out), "--claims", "stages", "--force"]) == 0
    assert main(["paper", "--out", str(tmp_path / "x"), "--claims", "no-such-claim"]) == 2
    # an --out that cannot be a directory is refused before anything runs
    (tmp_path / "file").write_text("")
    assert main(["paper", "--out", str(tmp_path / "file"), "--claims", "stages"]) == 2
    assert main(["paper", "--out", str(tmp_path / "file" / "sub"), "--claims", "stages"]) == 2


def test_iff_rule_pass_and_fail():
    agree = {"a": {"condition_2_7_holds": True, "poisson": True},
             "b": {"condition_2_7_holds": False, "poisson": False}}
    assert iff_verdict(agree, "poisson") == "confirmed"
    disagree = dict(agree, c={"condition_2_7_holds": False, "poisson": True})
    assert iff_verdict(disagree, "poisson") == "refuted"


def test_formula_4_3_as_printed_is_not_poisson_but_the_composition_is():
    printed, sequential = formula_4_3(BODY), formula_4_3_sequential(BODY)
    adj = jaxsplit.splitting(BODY, "lie-trotter-adjoint")

    def measure(x, h):  # everything at one (x, h): one compilation
        return (poisson_defect(printed, hat, x, h), poisson_defect(sequential, hat, x, h),
                jnp.max(jnp.abs(sequential(x, h) - adj(x, h))))

    d_printed, d_sequential, gap = jax.jit(jax.vmap(measure))(STATES, STEPS)
    assert float(jnp.min(d_printed[-8:])) >= PRINTED_FLOOR  # must fail (h >= 0.44)
    assert float(jnp.max(d_sequential)) <= POISSON_TOL  # must pass
    assert float(jnp.max(gap)) <= EQUAL_TOL


def test_example_3_1_one_stage_maps_are_poisson_off_the_printed_condition():
    a, b, big_a, h = 0.5, 1.0, 1.0, 0.3  # paper: Poisson only at h = 1/((2b - a)A) = 2/3
    system = jaxsplit.example_3_1(big_a, 2.0, 0.0)
    step = _one_stage_step(system, jnp.asarray(a), jnp.asarray(b))
    same = jaxsplit.runge_kutta(system, jaxsplit.ButcherTableau("one", ((a,),), (b,), 0))
    xs = jax.random.normal(jax.random.PRNGKey(10), (32, 2))
    def measure(x):  # one compilation for both
        return poisson_defect(step, system.poisson_matrix, x, h), jnp.max(jnp.abs(step(x, h) - same(x, h)))

    d, gap = jax.jit(jax.vmap(measure))(xs)
    assert float(jnp.max(d)) <= POISSON_TOL
    assert float(jnp.max(gap)) <= EQUAL_TOL


def test_audit_needs_float64(tmp_path):
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(jaxsplit.InputError, match="x64"):
            jaxsplit.audit_paper(tmp_path / "a")
    finally:
        jax.config.update("jax_enable_x64", True)


# ---------------------------------------------------------------- the rules behind the new wording
THRESHOLD_TOL = 1e-10  # |h* − exact|: departures count from |tr/2| > 1 + TAU_TOL, so h* is late by
# TAU_TOL / |d(tr/2)/dh| (2.5e-11 for the Euler family), plus the bisection's resolution


def test_question_verdict_answered_only_when_every_part_is_decided():
    assert question_verdict({"a": "no", "b": "yes"}) == "answered"
    assert question_verdict({"a": "no", "b": None}) == "not-checkable"  # must fail: one part undecided
    assert question_verdict({}) == "not-checkable"
    assert {"answered", "not-checkable"} <= set(VERDICTS)


def test_answer_from_defect_round_off_is_no_violation_is_yes_between_is_undecided():
    assert answer_from_defect(3e-15) == "no"
    assert answer_from_defect(1e-3) == "yes"
    assert answer_from_defect(1e-10) is None
    assert answer_from_defect(math.nan) is None


def _family(kind):
    """2x2 det-1 families with known half-traces: symplectic Euler on the oscillator (tr/2 = 1 − h²/2,
    leaves the circle through −1 at h = 2), a rotation (stays on), a hyperbolic shear (off at once)."""
    if kind == "euler":
        return lambda h: 0.5 * jnp.trace(jnp.array([[1.0, h], [-h, 1.0 - h**2]]))
    return {"rotation": jnp.cos, "hyperbolic": jnp.cosh}[kind]


def test_first_departure_finds_the_exact_threshold_and_the_families_that_never_leave():
    grid = jnp.exp(jnp.linspace(math.log(0.01), math.log(3.0), 40))
    kinds = ("euler", "rotation", "hyperbolic")
    found = jax.jit(lambda: [first_departure(_family(k), grid) for k in kinds])()  # one compilation
    (h_star, status), (h_rot, status_rot), (h_hyp, status_hyp) = found
    assert int(status) == 1 and abs(float(h_star) - 2.0) <= THRESHOLD_TOL
    assert float(_family("euler")(h_star)) < -1  # leaves through −1
    assert int(status_rot) == 0 and math.isnan(float(h_rot))  # must fail: stays on the circle
    assert int(status_hyp) == 2 and float(h_hyp) == float(grid[0])


def test_tangent_block_of_lie_trotter_at_an_equilibrium_is_area_preserving():
    step = jaxsplit.splitting(RigidBody(jnp.array([2.0, 1.5, 1.0])), "lie-trotter")
    dets = jax.jit(jax.vmap(lambda axis, h: jnp.linalg.det(tangent_block(step, axis, h))))(
        jnp.array([0, 1, 2]), jnp.array([0.3, 1.7, 4.0]))
    assert float(jnp.max(jnp.abs(dets - 1))) <= POISSON_TOL


def _row(exact, status, imag=0.0, product=0.0):
    return {"exact flow": exact, "status": status, "max |Im λ| just past": imag,
            "|λ1·λ2 − 1| just past": product}


def test_departure_scenario_needs_a_real_pair_with_product_one():
    assert _departure_scenario({"a": _row("elliptic", 1), "b": _row("hyperbolic", 2)}) == "yes"
    assert _departure_scenario({"a": _row("elliptic", 0), "b": _row("hyperbolic", 2)}) == "no"
    assert _departure_scenario({"a": _row("elliptic", 1, imag=0.3)}) is None  # not onto the real line
    assert _departure_scenario({"a": _row("elliptic", 1, product=1e-3)}) is None  # product not 1


def test_crossover_time_measured_extrapolated_or_never():
    t = np.linspace(0.0, 1000.0, 1001)
    when, how, p = crossover_time(t, 1e-10 * t, 1e-3)  # linear drift reaches 1e-3 at t = 1e7
    assert how == "extrapolated" and abs(p - 1) <= 1e-9 and abs(when / 1e7 - 1) <= 1e-9
    when, how, _ = crossover_time(t, 1e-10 * t**2, 1e-3)
    assert how == "extrapolated" and abs(when / math.sqrt(1e7) - 1) <= 1e-9
    when, how, _ = crossover_time(t, 1e-10 * t, 1e-8)  # already above within the samples
    assert how == "measured" and when == 101.0
    when, how, _ = crossover_time(t, 1e-9 * (1.5 + np.sin(t)), 1e-3)  # must fail: bounded, no crossover
    assert how == "never" and when is None


def test_report_numbers_have_three_significant_digits():
    assert number(0.010051984189153262) == "0.0101"
    assert number(2.5624e4) == "2.56e4" and number(1.2485306908121971e-08) == "1.25e-8"
    assert number(1000.0) == "1000" and number(7) == "7" and number(True) == "yes"
    assert cell(None) == "—" and cell([0.9191, 1.0512]) == "0.919, 1.05"
    assert cell({"h": 0.075, "error": 0.010051984189153262}) == "h: 0.075; error: 0.0101"


# ---------------------------------------------------------------- interrupted audits keep every finished claim
class _Abandoned(Exception):
    """Raised by the faked ``os._exit`` of the signal policy (the process would end here)."""


def _fake_registry(monkeypatch, kill_at=None):
    """Four cheap claim functions in two sections (one records two ids, one draws a figure) in
    place of the paper's; the one numbered ``kill_at`` sends SIGTERM to this process as it
    starts (deterministic: the signal lands inside a claim). Returns the calls made."""
    import os
    import signal

    from jaxsplit.cli import _signals
    from jaxsplit.paper import _audit, _figures
    from jaxsplit.paper._records import record

    calls = []

    def claim(number, ids, figure=False):
        def measure(ctx):
            calls.append(number)
            if number == kill_at:
                os.kill(os.getpid(), signal.SIGTERM)
            records = [record(cid, f"statement {cid}", "confirmed", {"measured": 0.5 * number + k})
                       for k, cid in enumerate(ids)]
            return records, ({ids[0]: np.linspace(0.0, number, 5)} if figure else None)
        return ids, measure

    claims = (claim(1, ("a",)), claim(2, ("b1", "b2")), claim(3, ("c",), figure=True), claim(4, ("d",)))
    monkeypatch.setattr(_audit, "CLAIMS", claims)
    monkeypatch.setattr(_audit, "CLAIM_IDS", ("a", "b1", "b2", "c", "d"))
    monkeypatch.setattr(_audit, "SECTION_OF", {"a": "§A", "b1": "§A", "b2": "§A", "c": "§B", "d": "§B"})

    def plot(data):
        fig, ax = _figures._plt().subplots(figsize=(2, 2))
        ax.plot(data)
        return fig

    monkeypatch.setitem(_figures._PLOTS, "c", (plot, "c_figure.png", "the figure of c"))
    monkeypatch.setattr(_signals.os, "_exit", lambda code: (_ for _ in ()).throw(_Abandoned(code)))
    return calls


def _without_timings(report: str) -> str:
    return report.split("## Run time per claim")[0]


@pytest.mark.parametrize("kill_at,kept", [(1, []), (2, ["a"]), (4, ["a", "b1", "b2", "c"])],
                         ids=["early", "middle", "late"])
def test_an_interrupted_audit_keeps_every_finished_claim_and_resumes_to_the_same_report(
        kill_at, kept, monkeypatch, tmp_path, capfd):
    reference = tmp_path / "reference"
    _fake_registry(monkeypatch)
    assert main(["paper", "--out", str(reference)]) == 0
    capfd.readouterr()
    calls = _fake_registry(monkeypatch, kill_at=kill_at)
    out = tmp_path / "audit"
    with pytest.raises(_Abandoned) as ended:
        main(["paper", "--out", str(out)])
    assert ended.value.args == (130,)
    err = capfd.readouterr().err
    assert f"{len(kept)} of 5 claims are saved in {out}" in err and "--resume" in err, err
    records = json.loads((out / "claims.json").read_text())
    want = {r["id"]: r for r in json.loads((reference / "claims.json").read_text())}
    assert [r["id"] for r in records if r["verdict"] != "not run"] == kept
    assert all(r == want[r["id"]] for r in records if r["id"] in kept)  # finished claims: whole, as measured
    report = (out / "report.md").read_text()
    assert all(f"### {cid} — not run" in report for cid in want if cid not in kept)
    assert (out / "c_figure.png").exists() == ("c" in kept)
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []  # no lock, no temporary
    calls = _fake_registry(monkeypatch)
    assert main(["paper", "--out", str(out), "--resume"]) == 0
    assert calls == [n for n in (1, 2, 3, 4) if n >= kill_at]  # only the claims not run
    assert (out / "claims.json").read_text() == (reference / "claims.json").read_text()
    assert _without_timings((out / "report.md").read_text()) == _without_timings((reference / "report.md").read_text())
    assert (out / "c_figure.png").exists()


def test_resume_needs_an_audit_and_keeps_its_claims(monkeypatch, tmp_path, capsys):
    _fake_registry(monkeypatch)
    assert main(["paper", "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err and not (tmp_path / "none").exists()
    assert main(["paper", "--out", str(tmp_path / "a"), "--claims", "a,c"]) == 0
    assert main(["paper", "--out", str(tmp_path / "a"), "--resume", "--claims", "d"]) == 2
    assert "--claims has no effect here" in capsys.readouterr().err
    assert main(["paper", "--out", str(tmp_path / "a"), "--claims", "d"]) == 2
    assert "already holds an audit; pass --resume" in capsys.readouterr().err
