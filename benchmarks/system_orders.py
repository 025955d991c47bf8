"""What orders do Strang, Suzuki 5, Kahan–Li 6 and Kahan–Li 8 reach on the spinning-body systems,
and how does the fitted order depend on the fit window?

The procedure of ``tests/test_systems_long_runs.py::test_orders_on_two_parameter_sets`` (its
systems, parameter sets, ladder, T and references), recording every fitted order: the test's
window (errors in [1e-12, 1e-4], largest sub-step |w| h ρ <= 0.5), the same errors without the
step bound, and Kahan–Li 8's local slopes (consecutive ladder points inside the window).

``python benchmarks/system_orders.py``
"""

import itertools
import sys
import time
from pathlib import Path

import jax

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
jax.config.update("jax_enable_x64", True)

import numpy as np
from _common import finish, header, log, machine_info
from test_systems_long_runs import COUNTS, MAX_ANGLE, ORDER_WINDOW, PATHS, SCHEMES, TAU

import jaxsplit


def main():
    start = time.perf_counter()
    out = machine_info("python benchmarks/system_orders.py")
    rows = []
    for label, family, split, exact, cases in PATHS:
        length = max(len(jaxsplit.splitting(family(cases[0][0]), s, split).word) for s in SCHEMES + ("kahan-li-10",))
        for k, (params, x0) in enumerate(cases):
            system = family(params)
            rate = float(system.max_rate(x0))
            reference_step = jaxsplit.roll(jaxsplit.splitting(system, "kahan-li-10", split), length)
            for name in SCHEMES:
                comp = jaxsplit.splitting(system, name, split)
                t_end = TAU[jaxsplit.schemes[name].order] / rate
                reference = (jaxsplit.exact_solution(system, x0, t_end) if exact else
                             jaxsplit.integrate(reference_step, x0, t_end / 400, 400).final)
                hs, errors = jaxsplit.global_errors(jaxsplit.roll(comp, length), x0, t_end, COUNTS, reference)
                largest = max(abs(w) for _, w in comp.word)
                bounded = jaxsplit.fit_order(hs, errors, ORDER_WINDOW, max_step=MAX_ANGLE / (largest * rate))
                free = jaxsplit.fit_order(hs, errors, ORDER_WINDOW)
                inside = np.flatnonzero(free.used)
                local = [float(np.log(errors[i] / errors[j]) / np.log(hs[i] / hs[j]))
                         for i, j in itertools.pairwise(inside)]
                rows.append({"system": label, "parameter_set": k + 1, "scheme": name,
                             "nominal": jaxsplit.schemes[name].order, "order": bounded.order,
                             "points": int(bounded.used.sum()),
                             "window_errors": [float(errors[bounded.used].min()), float(errors[bounded.used].max())],
                             "order_without_step_bound": free.order, "local_slopes": local})
                log(f"{label} #{k + 1} {name}: {bounded.order:.2f} ({int(bounded.used.sum())} points), "
                    f"without the step bound {free.order:.2f}")
    out["rows"] = rows
    lines = header(out, "Orders on the spinning-body systems (`python benchmarks/system_orders.py`)")
    lines += [("The test's fit: errors in [1e-12, 1e-4] and largest sub-step |w| h ρ <= 0.5; the errors the fit "
               "used; the same errors without the step bound; local slopes between consecutive points in the "
               "error window (largest steps first)."), "",
              "| system | set | scheme | order (test's fit) | points | errors used | without step bound | local slopes |",
              "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = r["window_errors"]
        slopes = " ".join(f"{s:.2f}" for s in r["local_slopes"])
        lines.append(f"| {r['system']} | {r['parameter_set']} | {r['scheme']} | {r['order']:.2f} | {r['points']} | "
                     f"{lo:.1e} … {hi:.1e} | {r['order_without_step_bound']:.2f} | {slopes} |")
    kl8 = [r for r in rows if r["scheme"] == "kahan-li-8"]
    deviation = {name: max(abs(r["order"] - r["nominal"]) for r in rows if r["scheme"] == name) for name in SCHEMES}
    lines += ["", "### Reading", "",
              "Largest |fitted − nominal| with the test's fit: " + ", ".join(
                  f"{name} {d:.2f}" for name, d in deviation.items()) + ". Kahan–Li 8 is fitted from "
              f"{min(r['points'] for r in kl8)}–{max(r['points'] for r in kl8)} points (errors "
              f"{min(r['window_errors'][0] for r in kl8):.1e} … {max(r['window_errors'][1] for r in kl8):.1e}); "
              "without the step bound its fit moves to "
              f"{min(r['order_without_step_bound'] for r in kl8):.2f}–{max(r['order_without_step_bound'] for r in kl8):.2f}: "
              "the fitted order of a high-order scheme depends on the window, which goes with the figure."]
    out["largest_deviation"] = deviation
    finish("system_orders", out, lines, start)


if __name__ == "__main__":
    main()
