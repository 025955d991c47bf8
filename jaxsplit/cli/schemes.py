"""``jaxsplit schemes``: the registry as a table."""

from .._schemes import schemes


def add_parser(sub):
    p = sub.add_parser("schemes", help="list the composition schemes",
                       description="List every registered scheme: name, order, stages, form, citation.")
    p.set_defaults(func=run)


def run(args):
    rows = [(s.name, str(s.order), str(s.stages), s.form, s.citation) for s in map(schemes.get, schemes)]
    widths = [max(len(r[i]) for r in rows + [("name", "order", "stages", "form", "")]) for i in range(4)]
    header = ("name", "order", "stages", "form", "citation")
    for row in [header] + rows:
        print("  ".join(c.ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
