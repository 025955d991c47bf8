"""``jaxsplit schemes``: the registry as a table (or JSON)."""

import argparse

from ..core._compose import merge, word
from ..core._schemes import schemes
from . import _metadata

# What "stages" counts in each form (the registry's Scheme.stages); the flows columns count
# the same thing for every form: the sub-flows one step evaluates.
STAGE_UNITS = {"symmetric": "Strang steps", "lie-adjoint": "Lie-Trotter steps and adjoints",
               "partitioned": "B flows (of e^{a1 hA} e^{b1 hB} ... e^{a(s+1) hA})"}
PIECES = (2, 3)

EXAMPLES = """\
examples:
  jaxsplit schemes                 # name, order, stages, form, sub-flows per step, citation
  jaxsplit schemes --json          # one JSON object: {"schemes": [...]} with the coefficients

Every name works with --scheme of simulate, check and sweep; triple-jump-N resolves for any
even N >= 2. Partitioned schemes need --split casimir (two pieces).
"""


def add_parser(sub):
    p = sub.add_parser("schemes", help="list the composition schemes",
                       description="List every registered scheme: name, order, stages (counted per form: "
                                   "see the legend under the table), form, the sub-flows one step evaluates with "
                                   "a split into 2 and 3 pieces, citation.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", action="store_true", help="print one JSON object (with the coefficients)")
    p.set_defaults(func=run)


def flows_per_step(scheme, n_pieces: int) -> int | None:
    """Sub-flows one step evaluates with ``n_pieces`` pieces (adjacent ones of a piece merged;
    a processed scheme's kernel), None when the form does not fit that many."""
    return len(merge(word(scheme, n_pieces))) if scheme.pieces_allowed(n_pieces) else None


def run(args):
    table = [schemes[name] for name in schemes]
    if args.json:
        _metadata.print_json({"schemes": [
            {"name": s.name, "order": s.order, "stages": s.stages, "stages_unit": STAGE_UNITS[s.form], "form": s.form,
             "flows_per_step": {str(n): flows_per_step(s, n) for n in PIECES},
             "symmetric": s.symmetric, "citation": s.citation, "coefficients": list(s.coefficients),
             "processor": list(s.processor)}
            for s in table]})
        return 0
    header = ("name", "order", "stages", "form", "flows/2", "flows/3", "citation")
    rows = [header] + [(s.name, str(s.order), str(s.stages), s.form + (" (processed)" if s.processed else ""),
                        *(str(flows_per_step(s, n) or "-") for n in PIECES), s.citation) for s in table]
    widths = [max(len(r[i]) for r in rows) for i in range(len(header) - 1)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:-1], widths)) + "  " + row[-1])
    print("\nstages count, per form: " + "; ".join(f"{form}: {unit}" for form, unit in STAGE_UNITS.items())
          + ".\nflows/2, flows/3: the sub-flows one step evaluates with a split into 2 or 3 pieces (adjacent ones of "
          "a piece merged; a processed scheme: its kernel; '-': the form does not fit).")
    return 0
