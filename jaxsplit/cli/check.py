"""``jaxsplit check``: is a scheme Poisson on a body, and what order does it reach?

* Poisson defect (seed paper, Observation 3.1): max |DΦ Π(x) DΦᵀ − Π(Φ(x))| over random
  states x on the unit sphere, DΦ by ``jax.jacfwd``, Π = hat, one step of size ``--dt``.
* Measured order: global errors at ``--t-end`` over a ladder of 12 step counts (factor 16),
  log-log slope fitted over the errors inside ``ORDER_WINDOW`` (``jaxsplit._order``). The
  reference is the exact solution for a symmetric body, the 30-digit value for the standard
  case, and otherwise a Casimir-split 8th-order run whose own error is estimated (step
  halving) and reported.

Sizes are bounded up front (``_bounds``): the random states, the ladder's largest step
count, the scheme's stages. An order needs motion: a state that turns by less than
``MIN_MOTION`` radians over ``--t-end`` (a vanishing state, an equilibrium, a vanishing
time) is refused, since every error would sit at round-off and read as "exact".
"""

import argparse

import numpy as np

from ..checks._order import ORDER_WINDOW
from ..core._errors import InputError
from ..systems._rigid_body import PAPER_BODY, PAPER_M0, STANDARD_CASE
from . import _args, _bounds, _metadata, _problem, _signals

POISSON_TOL = 1e-12  # a Poisson map's defect is round-off: ~1e-16 per unit of |m|
ORDER_TOL = 0.3  # |measured - nominal order| allowed
LADDER_START = {1: 2000, 2: 200, 4: 30, 6: 16, 8: 10, 10: 4}  # at T = 10, as in the core tests
EXIT_FAILED = 1

EXAMPLES = """\
examples:
  jaxsplit check                                     # Lie-Trotter on the paper's symmetric body
  jaxsplit check --scheme kahan-li-6 --split casimir --inertia 3,2,1.5 --m0 0.2,0.9,0.3
  jaxsplit check --scheme strang --inertia 2,1,0.6667 --allow-nonphysical --json

exit status: 0 both checks pass; 1 a check fails (defect above 1e-12, or the measured order
more than 0.3 from the nominal one); 2 bad input.
"""


def add_parser(sub):
    p = sub.add_parser(
        "check", help="Poisson defect and measured order of a scheme on a body",
        description="Measure the Poisson defect (jacfwd, random unit states) and the "
                    "convergence order (global error ladder, log-log fit) of a scheme on a body.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scheme", default="lie-trotter", help="any name from `jaxsplit schemes` (default lie-trotter)")
    p.add_argument("--split", choices=("axes", "casimir"), default="axes", help="(default axes)")
    p.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                   help="axis of the Casimir shift, with --split casimir (default auto)")
    p.add_argument("--inertia", type=_args.vector3("--inertia", "I1,I2,I3"), default=PAPER_BODY, metavar="I1,I2,I3",
                   help=f"(default {_problem.fmt_vec(PAPER_BODY)})")
    p.add_argument("--m0", type=_args.vector3("--m0"), default=PAPER_M0, metavar="A,B,C",
                   help=f"initial state of the order measurement (default {_problem.fmt_vec(PAPER_M0)})")
    p.add_argument("--allow-nonphysical", action="store_true", help="accept bodies violating the triangle inequalities")
    p.add_argument("--dt", type=_args.nonzero_float, default=0.1, metavar="H", help="step of the Poisson check (default 0.1)")
    p.add_argument("--states", type=_args.positive_int, default=32, metavar="N",
                   help="random unit states of the Poisson check (default 32)")
    p.add_argument("--seed", type=_args.seed, default=0, help="seed of the random states (default 0)")
    p.add_argument("--t-end", type=_args.positive_float, default=10.0, metavar="T",
                   help="time of the order measurement (default 10)")
    p.add_argument("--start", type=_args.positive_int, metavar="N",
                   help="smallest step count of the ladder (default by order: 2000 for order 1 ... 4 for 10)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=run)


MAX_COUNT = 2**17  # largest step count of a ladder (12 runs saving every step: 12 x 2^17 states ~ 38 MB)
LADDER_FACTOR = 16  # a ladder spans start .. 16 x start
MAX_STATES = 100_000  # the Poisson check takes jacfwd of every random state in one batch (~1 KiB each)
MIN_MOTION = 0.1  # radians the state must turn over --t-end for an order (or exactness) to be measurable


def _measure_order(step, m0, t_end, reference, start, adapt=True):
    """Fit the order over ``ladder(start)``; when the errors miss the fit window, move the
    ladder (x16 or /16, at most twice) towards it. Returns (fit or None, note, counts, hs, errs)."""
    from ..checks._order import fit_order, global_errors, ladder

    tried = set()
    while True:
        tried.add(start)
        counts = ladder(start)
        hs, errs = global_errors(step, m0, t_end, counts, reference)
        try:
            return fit_order(hs, errs), "", counts, hs, errs
        except InputError:
            pass
        finite = errs[np.isfinite(errs)]
        if finite.size and finite.max() < ORDER_WINDOW[0]:
            return None, (f"all errors are at round-off (max {finite.max():.1e}): the splitting is exact "
                          "for this body, so no order can be measured"), counts, hs, errs
        too_big = not finite.size or np.median(finite) > ORDER_WINDOW[1]
        nxt = start * 16 if too_big else max(1, start // 16)
        if not adapt or nxt in tried or len(tried) >= 3 or nxt * 16 > MAX_COUNT:
            return None, (f"too few errors inside the fit window {ORDER_WINDOW} (errors "
                          f"{np.nanmin(errs):.1e} .. {np.nanmax(errs):.1e} for step counts {counts[0]}.."
                          f"{counts[-1]}); try another --start or --t-end"), counts, hs, errs
        start = nxt


def run(args):
    import jax
    import jax.numpy as jnp

    from ..checks._poisson import poisson_defect
    from ..systems._rigid_body import symmetric_solution
    from ..systems._splitting import splitting

    body = _problem.body(args.inertia, args.allow_nonphysical)
    scheme, shift = _problem.scheme_and_shift(args, body)
    m0_np = _problem.initial_state(args.m0, args.inertia)
    if not np.any(m0_np):
        raise InputError("--m0 must be non-zero (the order is measured on a moving state)")
    _check_motion(m0_np, np.asarray(args.inertia, dtype=np.float64), args.t_end)
    _bounds.at_most(args.states, MAX_STATES, "--states", "the Poisson check takes jacfwd of all states in one batch")
    if args.start is not None:
        _bounds.at_most(args.start, MAX_COUNT // LADDER_FACTOR, "--start",
                        f"its ladder runs up to {LADDER_FACTOR} x --start steps, saving every step")
    m0 = jnp.asarray(m0_np)
    kwargs = _problem.split_options(args.split, shift)
    step = splitting(body, scheme, args.split, **kwargs)

    # ---- Poisson defect over random unit states
    rng = np.random.default_rng(args.seed)
    xs = rng.standard_normal((args.states, 3))
    xs /= np.linalg.norm(xs, axis=1, keepdims=True)
    defects = np.asarray(jax.jit(jax.vmap(lambda x: poisson_defect(step, body, x, args.dt)))(jnp.asarray(xs)))
    worst = int(np.argmax(defects))
    poisson_ok = bool(defects[worst] <= POISSON_TOL)

    # ---- measured order
    t_end = args.t_end
    try:
        axis = body.symmetry_axis()
    except InputError:
        axis = None
    standard = (np.allclose(args.inertia, STANDARD_CASE.inertia, rtol=1e-15, atol=0)
                and np.allclose(args.m0, STANDARD_CASE.m0, rtol=1e-15, atol=0) and t_end == STANDARD_CASE.t_end)
    if axis is not None:
        reference, ref_kind, ref_acc = symmetric_solution(body, m0, t_end, axis=axis), "exact (symmetric body)", 0.0
    elif standard:
        reference, ref_kind, ref_acc = jnp.asarray(STANDARD_CASE.reference), "30-digit (standard case)", 1e-16
    else:
        from ..explore._sweep import reference_solution

        ref, acc = reference_solution(np.asarray(m0)[None], np.asarray(args.inertia, dtype=float)[None], t_end)
        reference, ref_kind, ref_acc = jnp.asarray(ref[0]), "kahan-li-8, Casimir split, step halving", float(acc[0])
    start = args.start or LADDER_START[max(k for k in LADDER_START if k <= max(1, min(scheme.order, 10)))]
    order_fit, note, counts, hs, errs = _measure_order(step, m0, t_end, reference, start, adapt=args.start is None)
    order_ok = order_fit is not None and abs(order_fit.order - scheme.order) <= ORDER_TOL
    exact_split = order_fit is None and bool(np.nanmax(errs) < ORDER_WINDOW[0])

    result = {
        "scheme": scheme.name, "nominal_order": scheme.order, "split": args.split,
        "shift_axis": shift if args.split == "casimir" else None,
        "inertia": list(args.inertia), "m0": list(args.m0),
        "poisson_defect_max": float(defects[worst]), "poisson_defect_median": float(np.median(defects)),
        "poisson_worst_state": xs[worst], "poisson_dt": args.dt, "poisson_states": args.states,
        "poisson_ok": poisson_ok,
        "measured_order": None if order_fit is None else order_fit.order,
        "order_points_used": None if order_fit is None else int(order_fit.used.sum()),
        "order_ok": bool(order_ok or exact_split), "order_note": note or None,
        "t_end": t_end, "step_counts": list(counts), "step_sizes": hs, "errors": errs,
        "reference": ref_kind, "reference_accuracy": ref_acc,
    }
    with _signals.current().critical():  # the measurements are done: print them whole
        _print(args, result, order_ok)
    return 0 if (poisson_ok and (order_ok or exact_split)) else EXIT_FAILED


def _check_motion(m0, inertia, t_end):
    """Refuse a run whose state hardly moves: |m0 x I^-1 m0| t_end / |m0| < MIN_MOTION."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        turn = float(np.linalg.norm(np.cross(m0, m0 / inertia)) * t_end / np.linalg.norm(m0))
    if not turn >= MIN_MOTION:
        what = ("--m0 is an equilibrium of this body (m0 x I^-1 m0 = 0)" if not np.any(np.cross(m0, m0 / inertia))
                else f"the state turns by only {turn:.2g} rad over --t-end {t_end:g}")
        raise InputError(f"{what}: no order can be measured (every error would be round-off); the check needs "
                         f">= {MIN_MOTION:g} rad: a longer --t-end, or an --m0 off the equilibria")


def _print(args, r, order_ok):
    if args.json:
        _metadata.print_json(r)
        return
    print(f"jaxsplit check: {r['scheme']} (nominal order {r['nominal_order']}), {r['split']} split"
          + (f" (shift axis {r['shift_axis']})" if r["split"] == "casimir" else "")
          + f", I = ({_problem.fmt_vec(r['inertia'])})")
    print(f"  Poisson defect, h = {r['poisson_dt']:g}, {r['poisson_states']} random unit states: max "
          f"{r['poisson_defect_max']:.2e} (median {r['poisson_defect_median']:.2e}) -> "
          f"{'Poisson to round-off' if r['poisson_ok'] else 'NOT Poisson'} (tolerance {POISSON_TOL:g})")
    counts = r["step_counts"]
    if r["measured_order"] is not None:
        print(f"  measured order {r['measured_order']:.3f} from {r['order_points_used']} of {len(counts)} step "
              f"counts ({counts[0]}..{counts[-1]}) to t = {r['t_end']:g} -> "
              f"{'agrees' if order_ok else 'DISAGREES'} (tolerance {ORDER_TOL})")
    else:
        print(f"  order: {r['order_note']}")
    print(f"  reference: {r['reference']}" + (f", accuracy {r['reference_accuracy']:.1e}"
                                               if r["reference_accuracy"] else ""))
