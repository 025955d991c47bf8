"""``jaxsplit paper``: audit the seed paper and write claims.json, report.md and figures."""

import os
import time

EXAMPLES = """examples:
  jaxsplit paper --out audit                     # all claims: measured ~95 s wall on 2 cores,
                                                 # 2.5-3 min while other jobs share them
  jaxsplit paper --out audit --force             # replace an earlier audit in DIR
  jaxsplit paper --out audit --claims thm4.1,rem4.4
Verdicts (confirmed, refuted, corrected, answered, not-checkable) are computed from the
measurements; report.md states the rule of each."""


def add_parser(sub):
    import argparse

    p = sub.add_parser("paper", help="audit every checkable claim of the seed paper",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Re-derive every checkable claim of the seed paper numerically; write "
                                   "DIR/claims.json (one record per claim, verdict computed from measurements), "
                                   "DIR/report.md and PNG figures.")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    p.add_argument("--force", action="store_true", help="overwrite an existing claims.json in DIR")
    p.add_argument("--claims", default=None, metavar="IDS",
                   help="comma-separated claim ids to run (default: all)")
    p.set_defaults(func=run)


def run(args):
    from ..paper._audit import audit_paper

    start = time.perf_counter()
    claims = None if args.claims is None else [c.strip() for c in args.claims.split(",") if c.strip()]
    records = audit_paper(args.out, claims, force=args.force)
    width = max(len(r["id"]) for r in records)
    for r in records:
        print(f"{r['id']:<{width}}  {r['verdict']}")
    counts = {}
    for r in records:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    summary = ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
    print(f"{len(records)} claims ({summary}) in {time.perf_counter() - start:.1f} s -> "
          f"{os.path.join(args.out, 'claims.json')}, {os.path.join(args.out, 'report.md')}")
    return 0
