"""``jaxsplit paper``: audit the seed paper and write claims.json, report.md and figures.

The audit (``paper.audit_paper``) writes its files itself; the CLI runs it in a private
staging directory inside the locked ``--out`` and then moves every file it produced into
place through the one writer (atomic renames, ``--force`` checked up front for every
name the audit can write). An interrupted audit leaves ``--out`` as it was.
"""

import os
import time

from ..core._errors import InputError
from . import _args, _io, _signals

EXAMPLES = """examples:
  jaxsplit paper --out audit                     # all claims (~40 s on 2 cores)
  jaxsplit paper --out audit --force             # replace an earlier audit in DIR
  jaxsplit paper --out audit --claims thm4.1,rem4.4
Verdicts (confirmed, refuted, corrected, not-checkable) are computed from the measurements."""

REPORTS = ("claims.json", "report.md")


def add_parser(sub):
    import argparse

    p = sub.add_parser("paper", help="audit every checkable claim of the seed paper",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Re-derive every checkable claim of the seed paper numerically; write "
                                   "DIR/claims.json (one record per claim, verdict computed from measurements), "
                                   "DIR/report.md and PNG figures.")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    p.add_argument("--force", action="store_true", help="overwrite an earlier audit's files in DIR")
    p.add_argument("--claims", type=_args.names("--claims"), default=None, metavar="IDS",
                   help="comma-separated claim ids to run (default: all)")
    p.set_defaults(func=run)


def _audit_files() -> tuple[str, ...]:
    """Every name the audit can write (the reports and the figures)."""
    from ..paper import _figures

    return REPORTS + tuple(name for name, _ in _figures._FIGURES.values())


def run(args):
    from ..paper._audit import CLAIM_IDS, audit_paper

    unknown = [c for c in args.claims or () if c not in CLAIM_IDS]
    if unknown:
        raise InputError(f"--claims: unknown claim id(s) {unknown}; known: {', '.join(CLAIM_IDS)}")
    start = time.perf_counter()
    with _io.Outputs(force=args.force) as outputs:
        out = outputs.directory(args.out, "--out directory")
        for name in _audit_files():  # claimed up front: nothing is overwritten without --force
            outputs.file(out / name, "audit")
        with outputs.staging(out) as stage:
            records = audit_paper(stage, args.claims, force=True)  # abandoned at once on a signal
            with _signals.current().critical():
                for name in sorted(os.listdir(stage)):
                    target = out / name
                    if target.resolve() not in outputs.claimed():
                        outputs.file(target, "audit")
                    outputs.move_in(stage / name, target)
                _print(records, start, out)
    return 0


def _print(records, start, out):
    width = max(len(r["id"]) for r in records)
    for r in records:
        print(f"{r['id']:<{width}}  {r['verdict']}")
    counts = {}
    for r in records:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    summary = ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
    print(f"{len(records)} claims ({summary}) in {time.perf_counter() - start:.1f} s -> "
          f"{out / 'claims.json'}, {out / 'report.md'}")
