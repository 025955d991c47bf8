"""``jaxsplit spins-audit``: the audit of spin integrators (``jaxsplit.paper._spins``): the
exact bond splitting, frozen-field sublattices, the sequential sweep, the spherical midpoint
and Heun on small lattices; writes spins.json, spins.md and two figures into --out."""

import argparse
import time

from . import _args

EXAMPLES = """examples:
  jaxsplit spins-audit --out spins                  # 3 lattices x 5 methods: ~12 min on 2 shared cores
  jaxsplit spins-audit --out spins --cases ring-6 --methods bonds,sublattice,sweep
Verdicts (Poisson map or not, energy conserved / bounded / drifts) are computed from the
measurements; spins.md states the rule of each."""


def add_parser(sub):
    p = sub.add_parser("spins-audit", help="audit spin integrators: Poisson defect, energy, |S_i|, order",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Measure, for the exact bond splitting and the schemes the spin-dynamics field "
                                   "uses, the Poisson defect against h, energy error and drift, |S_i|, the "
                                   "magnetisation where conserved, and the order; write DIR/spins.json, "
                                   "DIR/spins.md and PNG figures.")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    p.add_argument("--force", action="store_true", help="overwrite an earlier audit's files in DIR")
    p.add_argument("--cases", type=_args.names("--cases"), default=None, metavar="NAMES",
                   help="comma-separated cases (default: all: ring-6, square-4x4, honeycomb-2x2)")
    p.add_argument("--methods", type=_args.names("--methods"), default=None, metavar="NAMES",
                   help="comma-separated methods (default: bonds, sublattice, sweep, spherical-midpoint, heun)")
    p.add_argument("--no-figures", action="store_true", help="write no figures")
    p.set_defaults(func=run)


def run(args):
    from ..paper import _spins

    start = time.perf_counter()
    records, out = _spins.audit_spins(args.out, args.cases, args.methods, figures=not args.no_figures,
                                      force=args.force)
    for r in records:
        print(f"{r['case']:<14} {r['method']:<19} {r['poisson']['verdict']:<18} {r['energy']['verdict']}")
    print(f"{len(records)} runs in {time.perf_counter() - start:.1f} s -> {out / 'spins.json'}, {out / 'spins.md'}")
    return 0
