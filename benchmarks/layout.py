"""Which layout a batch of free-body states runs fastest in: components first or last.

``integrate`` runs a batch of bare m states (B, 3) either with its components first (each
component a contiguous row of the batch; a rotation rewrites its two rows with a ``stack``)
or with its components last (a rotation replaces two components with a ``select`` on the
component index, which keeps each state's three components in one loop iteration, so the
polynomial is evaluated once per state instead of once per rewritten row). ``for_run`` picks
components last for steps of more than ``so3.COMPONENTS_FIRST_UP_TO`` rotations whose angles
are bounded by ``so3.COMPONENTS_LAST_UP_TO``; this script measures both layouts on every case
(the constants set between calls to force each, each layout compiled once), calls
interleaved round by round, and checks the results agree bit for bit.

    python benchmarks/layout.py [--rounds 7] [--quick]

Writes ``benchmarks/results/layout.{md,json}``.
"""

import argparse
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import finish, fmt, header, interleaved, log, machine_info, paired_ratio

import jaxsplit
from jaxsplit.systems import so3

jax.config.update("jax_enable_x64", True)

# (scheme, bodies, steps, h): h = 0.5 is the work–precision runs' step (256 bodies, T = 10³, n = 2000)
CASES = (("strang", 32, 50_000, 0.05), ("strang", 256, 20_000, 0.05), ("strang", 4096, 2000, 0.05),
         ("strang", 10**4, 1000, 0.05), ("strang", 10**5, 100, 0.05),
         ("triple-jump-4", 256, 5000, 0.2), ("triple-jump-4", 10**4, 300, 0.2),
         ("kahan-li-6", 256, 2000, 0.5), ("yoshida-6a", 10**4, 100, 0.2),
         ("kahan-li-8", 32, 4000, 0.5), ("kahan-li-8", 256, 2000, 0.5), ("kahan-li-8", 4096, 200, 0.5),
         ("kahan-li-8", 10**5, 10, 0.5),
         ("blanes-casas-murua-8", 32, 4000, 0.5), ("blanes-casas-murua-8", 256, 640, 1.5625),
         ("blanes-casas-murua-8", 256, 1250, 0.8),
         ("blanes-casas-murua-8", 256, 2000, 0.5),
         ("blanes-casas-murua-8", 4096, 200, 0.5))
QUICK = (0, 2, 6, 10, 14)
# (COMPONENTS_FIRST_UP_TO, COMPONENTS_LAST_UP_TO) forcing each layout
LAYOUTS = {"components first": (10**9, 0.0), "components last": (0, float("inf"))}


def states(b):
    m = np.random.default_rng(0).standard_normal((b, 3))
    return jnp.asarray(m / np.linalg.norm(m, axis=1, keepdims=True))


def run_in(layout, step, x, h, n):
    def call():
        so3.COMPONENTS_FIRST_UP_TO, so3.COMPONENTS_LAST_UP_TO = LAYOUTS[layout]
        return jaxsplit.integrate(step, x, h, n).final.block_until_ready()
    return call


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="five cases, three rounds")
    args = parser.parse_args()
    rounds = 3 if args.quick else args.rounds
    cases = [CASES[k] for k in QUICK] if args.quick else CASES
    chosen = so3.COMPONENTS_FIRST_UP_TO, so3.COMPONENTS_LAST_UP_TO
    out = machine_info("python benchmarks/layout.py" + (" --quick" if args.quick else ""))
    start = time.perf_counter()
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
    out.update(components_first_up_to=chosen[0], components_last_up_to=chosen[1], cases={})
    lines = header(out, "Components first or last for a batch of free bodies (`benchmarks/layout.py`)") + [
        (f"Standard body, Casimir split, `integrate` as users call it with the layout forced; calls interleaved over "
         f"{rounds} rounds; run = median over rounds; ratio = median of the per-round ratios (first / last: above 1, "
         f"components last is faster); chosen = what `for_run` picks (components last for steps of more than "
         f"{chosen[0]} rotations whose angles are at most {chosen[1]}); identical: the two results bit for bit."), "",
        ("| scheme | bodies | steps | rotations per step | components first | components last | first / last "
         "| chosen | identical |"), "|---|---|---|---|---|---|---|---|---|"]
    for scheme, b, n, h in cases:
        step = jaxsplit.splitting(body, scheme, "casimir")
        x = states(b)
        calls = {layout: run_in(layout, step, x, h, n) for layout in LAYOUTS}
        results = {layout: np.asarray(call()) for layout, call in calls.items()}  # compiles each
        times = interleaved(calls, rounds)
        so3.COMPONENTS_FIRST_UP_TO, so3.COMPONENTS_LAST_UP_TO = chosen
        ratio = paired_ratio(times, "components first", "components last")
        rotations = step.flows_per_step
        pick = "first" if step.for_run(x, h).structure_of_arrays else "last"
        identical = bool(np.array_equal(*results.values()))
        entry = {layout: statistics.median(t) for layout, t in times.items()}
        entry.update(ratio=ratio, rotations=rotations, chosen=pick, identical=identical)
        out["cases"][f"{scheme}, {b} bodies, {n} steps"] = entry
        lines.append(f"| {jaxsplit.schemes[scheme].name} | {b:,} | {n:,} | {rotations} | "
                     f"{fmt(entry['components first'])} | {fmt(entry['components last'])} | {ratio:.2f} | {pick} | "
                     f"{'yes' if identical else 'NO'} |")
        log(lines[-1])
    finish("layout", out, lines, start, args.quick)


if __name__ == "__main__":
    main()
