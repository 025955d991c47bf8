"""``jaxsplit schemes``: the registry as a table (or JSON)."""

import argparse

from ..core._schemes import schemes
from . import _metadata

EXAMPLES = """\
examples:
  jaxsplit schemes                 # name, order, stages, form, citation
  jaxsplit schemes --json          # one JSON object: {"schemes": [...]} with the coefficients

Every name works with --scheme of simulate, check and sweep; triple-jump-N resolves for any
even N >= 2. Partitioned schemes need --split casimir (two pieces).
"""


def add_parser(sub):
    p = sub.add_parser("schemes", help="list the composition schemes",
                       description="List every registered scheme: name, order, stages, form, citation.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", action="store_true", help="print one JSON object (with the coefficients)")
    p.set_defaults(func=run)


def run(args):
    table = [schemes[name] for name in schemes]
    if args.json:
        _metadata.print_json({"schemes": [
            {"name": s.name, "order": s.order, "stages": s.stages, "form": s.form,
             "symmetric": s.symmetric, "citation": s.citation, "coefficients": list(s.coefficients),
             "processor": list(s.processor)}
            for s in table]})
        return 0
    header = ("name", "order", "stages", "form", "citation")
    rows = [header] + [(s.name, str(s.order), str(s.stages), s.form + (" (processed)" if s.processed else ""), s.citation)
                       for s in table]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:4], widths)) + "  " + row[4])
    return 0
