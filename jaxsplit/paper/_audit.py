"""The paper audit's registry of claims, grouped by the paper's sections, and its runner.

Seed paper: C. Hedrea, "The Lie–Trotter integrator in the dynamics of the symmetric free
rigid body". One function per claim (``_section2``, ``_section3``, ``_section4``,
``_section4_remarks``) MEASURES — integrations, ``jacfwd`` defects, tableau algebra,
eigenvalues — and returns its record(s) (``_records``: the verdict words with their rules,
the thresholds) and the data of its figure, if any. ``audit_paper`` runs the wanted claims,
renders the figures (``_figures``) and report.md (``_report``) in memory, and hands every file
to ``_output.write_outputs``, the one function that writes.
"""

import json
import math
import os
import time

import jax
import numpy as np

from ..core._errors import InputError
from . import _section2, _section3, _section4, _section4_remarks
from ._figures import figure_name, render
from ._output import MARKER, check_out_dir, write_outputs
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


def run_audit(claims=None, *, figures: bool = True) -> tuple[list[dict], dict]:
    """Run the audit; return (records, {file name: bytes}) with ``claims.json`` last.

    ``claims`` restricts the run to some ids (default: all). Needs float64
    (``jax.config.update("jax_enable_x64", True)``; the CLI does it). Writes nothing.
    """
    if not jax.config.jax_enable_x64:
        raise InputError("the paper audit measures at float64 round-off: enable jax_enable_x64 first")
    wanted = _wanted(claims)
    ctx, records, timings, drawn = {}, [], {}, {}
    for ids, claim in CLAIMS:
        if not any(cid in wanted for cid in ids):
            continue
        start = time.perf_counter()
        result, figure_data = claim(ctx)
        timings["+".join(ids)] = time.perf_counter() - start
        if os.environ.get("JAXSPLIT_AUDIT_VERBOSE"):
            print(f"{'+'.join(ids)}: {timings['+'.join(ids)]:.1f} s", flush=True)
        results = result if isinstance(result, list) else [result]
        records += [_jsonable(r) for r in results if r["id"] in wanted]
        drawn.update({cid: data for cid, data in (figure_data or {}).items() if cid in wanted})
    order = {c: i for i, c in enumerate(CLAIM_IDS)}
    records.sort(key=lambda r: order[r["id"]])
    rendered = render(drawn) if figures else {}
    files = {name: png for name, _, png in rendered.values()}
    captions = {cid: (name, caption) for cid, (name, caption, _) in rendered.items()}
    files["report.md"] = report_markdown(records, captions, timings, SECTION_OF).encode("utf-8")
    files[MARKER] = json.dumps(records, indent=2, ensure_ascii=False).encode("utf-8")
    return records, files


def audit_paper(out_dir, claims=None, *, figures: bool = True, force: bool = False) -> list[dict]:
    """Run the audit, write ``out_dir/claims.json``, ``out_dir/report.md`` and figures; return the records.

    ``claims`` restricts the run to some ids (default: all). The directory is checked before
    any work; every file is written atomically, ``claims.json`` last (its presence means a
    complete audit). ``jaxsplit paper`` writes the same files through the CLI's one writer
    (resolved paths, a lock on the directory).

    >>> import tempfile, jaxsplit
    >>> out = tempfile.mkdtemp()
    >>> [(r["id"], r["verdict"]) for r in jaxsplit.audit_paper(out, ["stages"], figures=False)]
    [('stages', 'corrected')]
    """
    out_dir = check_out_dir(out_dir, force)
    records, files = run_audit(claims, figures=figures)
    write_outputs(out_dir, files)
    return records
