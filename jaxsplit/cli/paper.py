"""``jaxsplit paper``: audit the seed paper and write claims.json, report.md and figures.

``paper._output.write_audit`` claims the files up front (``--force`` checked for each
before any work) inside the locked ``--out`` and writes them through the one writer after
every claim (atomic; claims.json last): SIGINT or SIGTERM at any moment keeps every
finished claim, report.md marks the rest "not run", and ``--resume`` runs only those.
"""

import time

from . import _args

EXAMPLES = """examples:
  jaxsplit paper --out audit                     # all claims: measured ~95 s wall on 2 cores,
                                                 # 2.5-3 min while other jobs share them
  jaxsplit paper --out audit --resume            # after Ctrl-C or a kill: run the claims not run
  jaxsplit paper --out audit --force             # replace an earlier audit in DIR
  jaxsplit paper --out audit --claims thm4.1,rem4.4
Verdicts (confirmed, refuted, corrected, answered, not-checkable) are computed from the
measurements; report.md states the rule of each.
exit status: 0 success; 2 bad input (one line on stderr, nothing run); 130 interrupted
(every finished claim is written, report.md marks the others "not run"; --resume runs them)."""


def add_parser(sub):
    import argparse

    p = sub.add_parser("paper", help="audit every checkable claim of the seed paper",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Re-derive every checkable claim of the seed paper numerically; write "
                                   "DIR/claims.json (one record per claim, verdict computed from measurements), "
                                   "DIR/report.md and PNG figures, rewritten after each claim.")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    p.add_argument("--force", action="store_true", help="overwrite an earlier audit's files in DIR")
    p.add_argument("--resume", action="store_true",
                   help="finish the interrupted audit in DIR: run only the claims it marks 'not run'")
    p.add_argument("--claims", type=_args.names("--claims"), default=None, metavar="IDS",
                   help="comma-separated claim ids to run (default: all)")
    p.set_defaults(func=run)


def run(args):
    from ..paper import output_names
    from ..paper._output import write_audit

    without = "without --resume (a resumed audit runs the claims it was started with)"
    _args.refuse_unused(args, {"claims": (not args.resume, without)})
    if args.claims is not None:
        output_names(args.claims)  # unknown ids refused before the directory is touched
    start = time.perf_counter()
    write_audit(args.out, args.claims, force=args.force, resume=args.resume,
                on_done=lambda records, out: _print(records, start, out))
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
