"""report.md of the paper audit, as text: the verdict rules, a summary table, then every claim
under its paper section with its notes, its measured evidence (numbers to 3 significant
digits; the full precision is in claims.json) and its figure, each figure once."""

import math
import re

from ._records import NOT_RUN, ORDER_TOL, ROUND_OFF, VERDICTS

_SUBSCRIPT = re.compile(r"(?:(?<=[\u0370-\u03ff])|(?<=\b[A-Z]))_(?=[^\W_](?![^\W_]))")  # Π_0, ω_k, X_F
_LABELS = (("condition_2_7", "(2.7)"),)  # evidence keys spelt for code -> for a reader


def _label(key) -> str:
    """An evidence key for a reader: underscores become spaces, except in subscripts."""
    text = str(key)
    for old, new in _LABELS:
        text = text.replace(old, new)
    keep = {m.start() for m in _SUBSCRIPT.finditer(text)}
    return "".join(" " if c == "_" and i not in keep else c for i, c in enumerate(text))


def _esc(text) -> str:
    """Text for a Markdown table cell."""
    return str(text).replace("|", "\\|")


def number(v, digits=3) -> str:
    """A number for a reader: integers as such, others to ``digits`` significant digits, short exponents."""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if not math.isfinite(v):
        return str(v)
    if v == int(v) and abs(v) < 1e4:
        return str(int(v))
    mantissa, _, exponent = f"{v:.{digits}g}".partition("e")
    return f"{mantissa}e{int(exponent)}" if exponent else mantissa


def cell(v) -> str:
    """Any evidence value as one line of text; None (not applicable) as a dash."""
    if v is None or v == "":
        return "—"
    if isinstance(v, (bool, int, float)):
        return number(v)
    if isinstance(v, list):
        return ", ".join(cell(x) for x in v)
    if isinstance(v, dict):
        return "; ".join(f"{_label(k)}: {cell(x)}" for k, x in v.items())
    return str(v)


def _is_scalar(v) -> bool:
    return not isinstance(v, dict)


def _evidence_lines(ev, depth=0):
    lines, indent = [], "  " * depth
    for k, v in ev.items():
        if isinstance(v, dict) and v and all(isinstance(x, dict) and all(map(_is_scalar, x.values()))
                                             for x in v.values()):
            cols = list(dict.fromkeys(c for row in v.values() for c in row))  # a table: rows of scalars
            header = "| | " + " | ".join(_esc(_label(c)) for c in cols) + " |"
            lines += [f"{indent}- **{_label(k)}**:", "", header, "|---" * (len(cols) + 1) + "|"]
            lines += [f"| {_esc(_label(name))} | " + " | ".join(_esc(cell(row.get(c))) for c in cols) + " |"
                      for name, row in v.items()]
            lines.append("")
        elif isinstance(v, dict) and len(v) <= 8 and all(map(_is_scalar, v.values())) \
                and max(len(str(x)) for x in v) <= 16:
            lines.append(f"{indent}- {_label(k)}: {cell(v)}")  # a short mapping on one line
        elif isinstance(v, dict):
            lines.append(f"{indent}- **{_label(k)}**:")
            lines += _evidence_lines(v, depth + 1)
        else:
            lines.append(f"{indent}- {_label(k)}: {cell(v)}")
    return lines


def report_markdown(records, figures, timings, section_of) -> str:
    """records: the claim records; figures: {claim id: (file name, caption)}; timings: {claim
    function: seconds}; section_of: {claim id: the paper section's title}."""
    intro = (f"Every verdict below was computed from the measurements at run time by `jaxsplit paper` "
             f"(`jaxsplit.paper`); structure defects <= {ROUND_OFF:g} count as round-off, measured orders "
             f"must lie within {ORDER_TOL:g} of the claimed ones. The text under each heading explains the "
             "measurement; the verdict comes only from the numbers listed. Full precision: `claims.json`.")
    title = "# Audit of the seed paper (Hedrea, Lie–Trotter integrator for the symmetric free rigid body)"
    lines = [title, "", intro, "", "Verdicts and their rules:", ""]
    lines += [f"- **{word}**: {rule}" for word, rule in VERDICTS.items()]
    if any(r["verdict"] == NOT_RUN for r in records):
        rule = ("no verdict: the audit stopped before this claim (`jaxsplit paper --out DIR --resume` runs the "
                "claims not run and keeps the others)")
        lines += [f"- **{NOT_RUN}**: {rule}"]
    lines += ["", "| id | verdict | claim |", "|---|---|---|"]
    lines += [f"| {r['id']} | **{r['verdict']}** | {_esc(r['statement'])} |" for r in records]
    counts = {}
    for r in records:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    lines += ["", "Totals: " + ", ".join(f"{counts[w]} {w}" for w in (*VERDICTS, NOT_RUN) if w in counts) + ".", ""]
    section = None
    for r in records:
        if section_of[r["id"]] != section:
            section = section_of[r["id"]]
            lines += [f"## {section}", ""]
        lines += [f"### {r['id']} — {r['verdict']}", ""] + ([f"> {r['statement']}", ""] if r["statement"] else [])
        if r.get("notes"):
            lines += [r["notes"], ""]
        lines += _evidence_lines(r["evidence"])
        if r["id"] in figures:
            name, caption = figures[r["id"]]
            lines += ["", f"![{caption}]({name})", "", f"*{caption}*"]
        lines.append("")
    kept = [r["id"] for r in records if r["verdict"] != NOT_RUN and not any(r["id"] in k.split("+") for k in timings)]
    if timings or kept:
        total = sum(timings.values())
        lines += ["## Run time per claim (s)", ""]
        if timings:
            lines += [", ".join(f"{k} {v:.1f}" for k, v in timings.items()) + f"; total {total:.0f} s.", ""]
        if kept:
            lines += [f"Kept from an earlier run (resumed): {', '.join(kept)}.", ""]
    return "\n".join(lines)
