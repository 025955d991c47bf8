"""Which Casimir shift and piece order make a scheme cheapest on the standard body? Error at
T = 10³ over 256 bodies against rotations spent, for every shift (the axis whose 1/I is
subtracted) and both orders of the two rotations, with the schemes that lead the
work–precision benchmark. Counts rotations, not seconds: every variant runs the same kernel.

    python benchmarks/split_choice.py

Writes ``benchmarks/results/split_choice.{md,json}``.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import header, log, machine_info, scheme_label, write
from work_precision import BODIES, T_END, reference, states

import jaxsplit

SCHEMES = {"kahan-li-8": (1250, 2500), "mclachlan-ss15": (1250, 2500), "blanes-moan-s10-prk": (2500, 5000),
           "kahan-li-6": (2500, 5000)}


def main():
    body = jaxsplit.RigidBody(jnp.asarray(BODIES["standard I = (2, 1, 2/3)"]), allow_nonphysical=True)
    m0 = jnp.asarray(states())
    reference_final = reference(body, m0)  # Kahan–Li 10 at sub-step angles <= 0.01, as in work_precision.py
    out = machine_info("python benchmarks/split_choice.py")
    out["rows"] = []
    for shift in (0, 1, 2):
        for reverse in (False, True):
            flows = body.casimir_split(shift)
            for scheme, counts in SCHEMES.items():
                step = jaxsplit.compose(flows[::-1] if reverse else flows, scheme)
                for n in counts:
                    final = jaxsplit.integrate(step, m0, T_END / n, n).final
                    error = float(np.max(np.abs(np.asarray(final) - reference_final)))
                    out["rows"].append({"shift": shift, "reversed": reverse, "scheme": scheme, "steps": n,
                                        "rotations_per_body": n * step.flows_per_step, "error": error})
                    log(f"shift {shift} reversed {reverse} {scheme} n={n}: {error:.2e}")
    auto = body.shift_axis("auto")
    lines = header(out, "Casimir shift and piece order (`benchmarks/split_choice.py`)")
    lines += [(f"Standard body, 256 random unit states, T = 10³; max error over the bodies against the "
              f"work–precision reference. The default shift (`shift=\"auto\"`, the middle 1/I) is {auto}."), "",
              "| scheme | steps | rotations per body | " + " | ".join(
                  f"shift {s}{', reversed' if r else ''}" for s in (0, 1, 2) for r in (False, True)) + " |",
              "|---|---|---|" + "---|" * 6]
    for scheme, counts in SCHEMES.items():
        for n in counts:
            rows = [r for r in out["rows"] if r["scheme"] == scheme and r["steps"] == n]
            lines.append(f"| {scheme_label(scheme)} | {n:,} | {rows[0]['rotations_per_body']:,} | "
                         + " | ".join(f"{r['error']:.2e}" for r in rows) + " |")
    write("split_choice", False, out, lines)


if __name__ == "__main__":
    main()
