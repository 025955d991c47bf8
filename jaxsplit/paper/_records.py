"""The audit's vocabulary: a claim record, the verdict words with their rules, the thresholds.

A record is ``{"id", "statement", "verdict", "evidence": {...numbers...}, "notes"}``. Every
verdict is decided at run time from the measurements in ``evidence``, by the rule written
next to its word in ``VERDICTS`` (the report prints these rules; nothing else documents
them). Thresholds are the named constants below.
"""

import numpy as np

VERDICTS = {
    "confirmed": "the measured property holds as stated",
    "refuted": "the measured property fails as stated",
    "corrected": "the statement as printed fails, but the correction given in the notes holds",
    "answered": "an open question of the paper: the measurements decide every part of it (the answers are "
                "in the evidence)",
    "not-checkable": "the claim has no numerical content, or the measurements do not decide it",
}

NOT_RUN = "not run"  # not a verdict: the record of a claim an interrupted audit did not reach
ROUND_OFF = 1e-12  # a structure defect at or below this is round-off (float64, O(1) states)
STRUCTURE_FLOOR = 1e-9  # a defect above this is a real violation, not round-off
ORDER_TOL = 0.3  # measured order within this of the claimed one
INVARIANT_FLOOR = 1e-8  # an invariant error above this is "not conserved"
SAME_RESULTS_FACTOR = 10.0  # Remark 4.2: "almost the same results" = errors within this factor


def record(cid, statement, verdict, evidence, notes=""):
    if verdict not in VERDICTS:
        raise AssertionError(f"{cid}: verdict {verdict!r}")
    return {"id": cid, "statement": statement, "verdict": verdict, "evidence": evidence, "notes": notes}


def holds(defect, tol=ROUND_OFF) -> bool:
    return bool(np.isfinite(defect) and defect <= tol)


def answer_from_defect(defect) -> str | None:
    """A yes/no question measured by a defect: "no" at round-off, "yes" above the structure
    floor, None (undecided) in between or when not finite."""
    if not np.isfinite(defect):
        return None
    if defect <= ROUND_OFF:
        return "no"
    return "yes" if defect > STRUCTURE_FLOOR else None


def question_verdict(answers: dict) -> str:
    """``answered`` when every part of a question has a measured answer, else ``not-checkable``."""
    return "answered" if answers and all(a is not None for a in answers.values()) else "not-checkable"
