"""The paper audit: record structure, CLI behaviour, and the measurements behind the key
verdicts (each with a must-pass and a must-fail case). The full audit (all ids, < 2 min)
is run by `jaxsplit paper --out DIR`; here a cheap subset runs end to end."""

import json

import jax
import jax.numpy as jnp
import pytest

import jaxsplit
from jaxsplit import PAPER_BODY, RigidBody, hat, poisson_defect
from jaxsplit.checks._poisson import random_unit_states
from jaxsplit.cli import main
from jaxsplit.paper._audit import (
    _PROVIDES,
    CLAIM_IDS,
    CLAIMS,
    VERDICTS,
    _iff_verdict,
    _one_stage_step,
    formula_4_3,
    formula_4_3_sequential,
)

ISSUE_IDS = ("ex2.1-i", "ex2.1-ii", "prop2.1", "prop2.2", "ex3.1-i", "ex3.1-ii", "ex3.1-iii", "ex3.1-iv",
             "prop3.1", "prop3.2", "thm4.1", "prop4.2", "order2", "order4", "order2n+2", "stages", "rem4.1",
             "rem4.2", "rem4.4", "rem4.5")
POISSON_TOL = 1e-12
PRINTED_FLOOR = 1e-4  # (4.3) as printed at h in [0.05, 0.5]: defect ~1e-3 .. 1e-1
EQUAL_TOL = 1e-14
SUBSET = ("ex2.1-i", "ex2.1-ii", "stages", "rem4.5")

BODY = RigidBody(jnp.asarray(PAPER_BODY))
STATES = random_unit_states(jax.random.PRNGKey(9), 64)
STEPS = jnp.linspace(0.05, 0.5, 64)


def test_every_issue_id_has_a_measurement():
    assert set(ISSUE_IDS) <= set(CLAIM_IDS)
    provided = {p for cid, _ in CLAIMS for p in _PROVIDES.get(cid, (cid,))}
    assert provided == set(CLAIM_IDS)


def test_cli_subset_end_to_end(tmp_path):
    out = tmp_path / "audit"
    assert main(["paper", "--out", str(out), "--claims", ",".join(SUBSET)]) == 0
    records = json.loads((out / "claims.json").read_text())
    assert [r["id"] for r in records] == list(SUBSET)
    for r in records:
        assert set(r) >= {"id", "statement", "verdict", "evidence"}
        assert r["verdict"] in VERDICTS
        assert r["statement"] and "\n" not in r["statement"]
        numbers = [v for v in json.dumps(r["evidence"]).replace(",", " ").split() if any(c.isdigit() for c in v)]
        assert numbers, r["id"]
    report = (out / "report.md").read_text()
    assert all(f"## {cid}" in report for cid in SUBSET)
    assert (out / "rem45_orbit.png").stat().st_size > 1000
    # a second run refuses to overwrite; --force allows it
    assert main(["paper", "--out", str(out), "--claims", "stages"]) == 2
    assert main(["paper", "--out", str(out), "--claims", "stages", "--force"]) == 0
    assert main(["paper", "--out", str(tmp_path / "x"), "--claims", "no-such-claim"]) == 2


def test_iff_rule_pass_and_fail():
    agree = {"a": {"condition_2_7_holds": True, "poisson": True}, "b": {"condition_2_7_holds": False, "poisson": False}}
    assert _iff_verdict(agree, "poisson") == "confirmed"
    disagree = dict(agree, c={"condition_2_7_holds": False, "poisson": True})
    assert _iff_verdict(disagree, "poisson") == "refuted"


def test_formula_4_3_as_printed_is_not_poisson_but_the_composition_is():
    defect = jax.jit(jax.vmap(lambda step, x, h: poisson_defect(step, hat, x, h), in_axes=(None, 0, 0)),
                     static_argnums=0)
    printed, sequential = formula_4_3(BODY), formula_4_3_sequential(BODY)
    assert float(jnp.min(defect(printed, STATES[:8], STEPS[-8:]))) >= PRINTED_FLOOR  # must fail
    assert float(jnp.max(defect(sequential, STATES, STEPS))) <= POISSON_TOL  # must pass
    adj = jaxsplit.splitting(BODY, "lie-trotter-adjoint")
    gap = jax.jit(jax.vmap(lambda x, h: jnp.max(jnp.abs(sequential(x, h) - adj(x, h)))))(STATES, STEPS)
    assert float(jnp.max(gap)) <= EQUAL_TOL


def test_example_3_1_one_stage_maps_are_poisson_off_the_printed_condition():
    a, b, big_a, h = 0.5, 1.0, 1.0, 0.3  # paper: Poisson only at h = 1/((2b - a)A) = 2/3
    system = jaxsplit.example_3_1(big_a, 2.0, 0.0)
    step = _one_stage_step(system, jnp.asarray(a), jnp.asarray(b))
    xs = jax.random.normal(jax.random.PRNGKey(10), (32, 2))
    d = jax.jit(jax.vmap(lambda x: poisson_defect(step, system.poisson_matrix, x, h)))(xs)
    assert float(jnp.max(d)) <= POISSON_TOL
    same = jaxsplit.runge_kutta(system, jaxsplit.ButcherTableau("one", ((a,),), (b,), 0))
    gap = jax.jit(lambda x: jnp.max(jnp.abs(step(x, h) - same(x, h))))(xs[0])
    assert float(gap) <= EQUAL_TOL


def test_audit_needs_float64(tmp_path):
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(jaxsplit.InputError, match="x64"):
            jaxsplit.audit_paper(tmp_path / "a")
    finally:
        jax.config.update("jax_enable_x64", True)
