"""`jaxsplit check` with its default settings for every registered scheme on three bodies.

The acceptance of issue 13 (point 2): exit status 0 everywhere, each order either agreeing
with the nominal one or "not measurable here" with the reason. In-process through
``jaxsplit.cli.main`` (JSON output); writes ``benchmarks/results/check_all_schemes.{md,json}``.

    PYTHONPATH=$PWD python benchmarks/check_all_schemes.py            # all schemes, three bodies
    PYTHONPATH=$PWD python benchmarks/check_all_schemes.py --quick    # the first body only
"""

import contextlib
import io
import json
import pathlib
import sys
import time

BODIES = {  # the default body, then two asymmetric ones (the default m0 0.6,0,0.8)
    "default (2,2,1)": [],
    "(3,2,1.5)": ["--inertia", "3,2,1.5"],
    "(1,2,2.5)": ["--inertia", "1,2,2.5"],
}


def main(quick: bool) -> int:
    import jaxsplit
    from jaxsplit.cli import main as cli

    rows, failures = [], 0
    for body, extra in list(BODIES.items())[: 1 if quick else None]:
        for name in jaxsplit.schemes:
            out = io.StringIO()
            start = time.perf_counter()
            with contextlib.redirect_stdout(out):
                status = cli(["check", "--scheme", name, "--json", *extra])
            r = json.loads(out.getvalue())
            rows.append({"body": body, "scheme": name, "exit": status, "split": r["split"],
                         "nominal": r["nominal_order"], "measured": r["measured_order"],
                         "verdict": r["order_verdict"], "note": r["order_note"], "poisson": r["poisson_defect_max"],
                         "seconds": time.perf_counter() - start})
            failures += status != 0
            print(f"{body:16s} {name:24s} exit {status} {r['order_verdict']:15s} "
                  f"{r['measured_order'] if r['measured_order'] is not None else float('nan'):7.3f}", flush=True)
    here = pathlib.Path(__file__).parent / "results"
    (here / "check_all_schemes.json").write_text(json.dumps(rows, indent=1))
    lines = ["# `jaxsplit check` with default settings, every registered scheme", "",
             ("Command: `PYTHONPATH=$PWD python benchmarks/check_all_schemes.py` "
              f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}). Exit status 0 for all: "
              f"{'yes' if failures == 0 else f'NO ({failures} failures)'}."), "",
             "| body | scheme | split | nominal | measured | verdict | exit | s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        measured = "—" if r["measured"] is None else f"{r['measured']:.3f}"
        lines.append(f"| {r['body']} | {r['scheme']} | {r['split']} | {r['nominal']} | {measured} | {r['verdict']} | "
                     f"{r['exit']} | {r['seconds']:.1f} |")
    notes = sorted({(r["verdict"], r["note"]) for r in rows if r["note"]})
    lines += ["", "Reasons given (verdicts other than 'agrees'):", ""] + [f"* {v}: {n}" for v, n in notes]
    (here / "check_all_schemes.md").write_text("\n".join(lines) + "\n")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main("--quick" in sys.argv))
