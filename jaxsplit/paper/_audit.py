"""The paper audit's registry of claims, grouped by the paper's sections, and its runner.

Seed paper: C. Hedrea, "The Lie–Trotter integrator in the dynamics of the symmetric free
rigid body". One function per claim (``_section2``, ``_section3``, ``_section4``,
``_section4_remarks``) MEASURES — integrations, ``jacfwd`` defects, tableau algebra,
eigenvalues — and returns its record(s) (``_records``: the verdict words with their rules,
the thresholds) and the data of its figure, if any. ``audit_paper`` runs the wanted claims,
renders the figures (``_figures``) and report.md (``_report``) in memory after each claim
(``audit_steps``), and ``_output.write_audit`` writes them as they come: an interrupted audit
keeps every finished claim, the rest marked ``not run``, and resumes.
"""

import json
import math
import os
import time

import jax
import numpy as np

from ..core._errors import InputError
from . import _section2, _section3, _section4, _section4_remarks
from ._figures import figure_caption, figure_name, render
from ._output import MARKER
from ._records import NOT_RUN
from ._report import report_markdown

SECTIONS = (
    ("§2 Numerical and symplectic integrators", _section2.CLAIMS),
    ("§3 Poisson integrators", _section3.CLAIMS),
    ("§4 The Lie–Trotter integrator of the symmetric free rigid body", _section4.CLAIMS),
    ("§4 Remarks", _section4_remarks.CLAIMS),
)
CLAIMS = tuple(entry for _, claims in SECTIONS for entry in claims)  # (ids it records, function)
CLAIM_IDS = tuple(cid for ids, _ in CLAIMS for cid in ids)
SECTION_OF = {cid: title for title, claims in SECTIONS for ids, _ in claims for cid in ids}


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else str(float(x))
    if isinstance(x, (np.ndarray, jax.Array)):
        return _jsonable(np.asarray(x).tolist())
    return x


def output_names(claims=None, *, figures: bool = True) -> tuple[str, ...]:
    """Every file an audit of ``claims`` writes (known before it runs: the CLI claims them)."""
    wanted = _wanted(claims)
    drawn = tuple(figure_name(cid) for cid in wanted if figures and figure_name(cid) is not None)
    return tuple(dict.fromkeys(drawn)) + ("report.md", MARKER)


def _wanted(claims):
    wanted = CLAIM_IDS if claims is None else tuple(claims)
    unknown = [c for c in wanted if c not in CLAIM_IDS]
    if unknown:
        raise InputError(f"unknown claim id(s) {unknown}; known: {', '.join(CLAIM_IDS)}")
    if not wanted:
        raise InputError("no claim ids given: name at least one (or none for all)")
    return wanted


def require_x64() -> None:
    if not jax.config.jax_enable_x64:
        raise InputError("the paper audit measures at float64 round-off: enable jax_enable_x64 first")


def _run_claim(claim, ctx):
    """One claim function's (result, figure data): the unit of work the audit keeps."""
    return claim(ctx)


def not_run(cid: str) -> dict:
    """The record of a claim the audit did not reach (interrupted): no verdict, no evidence."""
    return {"id": cid, "statement": "", "verdict": NOT_RUN, "evidence": {},
            "notes": "Not run: the audit stopped before this claim; `jaxsplit paper --out DIR --resume` runs it."}


def audit_steps(claims=None, *, figures: bool = True, finished=()):
    """Run the audit one claim function at a time; first and after each, yield ``{file name:
    bytes}``: that function's figures, then report.md and ``claims.json`` of the whole audit
    so far (every record measured, the others marked ``not run``), so that writing each
    yield keeps every finished claim whatever stops the run next.

    ``finished``: records of an earlier run (with their figures already written) whose
    functions are not run again. Needs float64 (the CLI enables it). Writes nothing.
    """
    require_x64()
    wanted = _wanted(claims)
    done = {r["id"]: r for r in finished if r["id"] in wanted and r["verdict"] != NOT_RUN}
    ctx, timings = {}, {}
    todo = [(ids, claim) for ids, claim in CLAIMS
            if any(cid in wanted and cid not in done for cid in ids)]
    yield _report_files(wanted, done, {}, timings, figures)  # before any claim: every one not run (yet)
    for ids, claim in todo:
        start = time.perf_counter()
        result, figure_data = _run_claim(claim, ctx)
        key = "+".join(ids)
        timings[key] = time.perf_counter() - start
        if os.environ.get("JAXSPLIT_AUDIT_VERBOSE"):
            print(f"{key}: {timings[key]:.1f} s", flush=True)
        results = result if isinstance(result, list) else [result]
        done.update({r["id"]: _jsonable(r) for r in results if r["id"] in wanted})
        drawn = {cid: data for cid, data in (figure_data or {}).items() if cid in wanted}
        rendered = render(drawn) if figures else {}
        files = {name: png for name, _, png in rendered.values()}
        yield files | _report_files(wanted, done, rendered, timings, figures)


def _report_files(wanted, done, rendered, timings, figures) -> dict:
    """report.md and claims.json (last) of the records ``done`` so far, in the registry's order."""
    records = [done.get(cid) or not_run(cid) for cid in CLAIM_IDS if cid in wanted]
    captions = {}
    for r in records:  # a finished claim's figure: rendered now or written by an earlier step or run
        if figures and r["verdict"] != NOT_RUN and figure_name(r["id"]) is not None:
            captions[r["id"]] = (figure_name(r["id"]), figure_caption(r["id"]))
    captions |= {cid: (name, caption) for cid, (name, caption, _) in rendered.items()}
    return {"report.md": report_markdown(records, captions, timings, SECTION_OF).encode("utf-8"),
            MARKER: json.dumps(records, indent=2, ensure_ascii=False).encode("utf-8")}


def run_audit(claims=None, *, figures: bool = True) -> tuple[list[dict], dict]:
    """Run the audit; return (records, {file name: bytes}) with ``claims.json`` last.

    ``claims`` restricts the run to some ids (default: all). Needs float64
    (``jax.config.update("jax_enable_x64", True)``; the CLI does it). Writes nothing.
    """
    files = {}
    for step in audit_steps(claims, figures=figures):
        files = {k: v for k, v in files.items() if k not in step} | step  # claims.json stays last
    return json.loads(files[MARKER]), files


def audit_paper(out_dir, claims=None, *, figures: bool = True, force: bool = False,
                resume: bool = False) -> list[dict]:
    """Run the audit, write ``out_dir/claims.json``, ``out_dir/report.md`` and figures; return the records.

    ``claims`` restricts the run to some ids (default: all). The directory is checked and
    locked before any work; after each claim the files are rewritten atomically (the claims
    not reached yet marked ``not run``), so an interrupted audit keeps every finished claim
    and ``resume=True`` runs only the rest. ``jaxsplit paper`` is this function.

    >>> import tempfile, jaxsplit
    >>> out = tempfile.mkdtemp()
    >>> [(r["id"], r["verdict"]) for r in jaxsplit.audit_paper(out, ["stages"], figures=False)]
    [('stages', 'corrected')]
    """
    from ._output import write_audit

    return write_audit(out_dir, claims, figures=figures, force=force, resume=resume)
