"""``jaxsplit check``: is a scheme Poisson on a system, and what order does it reach?

* Poisson defect (seed paper, Observation 3.1): max |DΦ Π(x) DΦᵀ − Π(Φ(x))| over random
  states x (unit m, or m of |m0|'s size, with a random attitude or unit Γ), DΦ by
  ``jax.jacfwd``, one step of size ``--dt``.
* Measured order: global errors at ``--t-end`` against a reference (the exact Jacobi
  elliptic solution of the free body, with or without its attitude; else a Kahan–Li 8 run
  refined until it agrees with half its steps, its own error reported). The ladder is
  chosen for the scheme: a probe over step counts 1, 2, 4, ..., 8192 finds where the errors
  lie between round-off and ``UPPER``, then up to 14 step counts over a factor 4 around the
  smallest such step size (distinct integers: fewer where the counts are small; every ladder
  through one compilation, ``roll``; the output states the ladder run). The order is the
  log-log slope over the smallest usable step sizes (within a factor ``TAIL``, at least
  ``MIN_FIT_POINTS`` of them, else not measurable here): the most asymptotic
  points above round-off (``ROUNDOFF`` ε |x| √n, ~10x the round-off measured at T = 10,
  or 10x the reference's error). It agrees when it is within ``ORDER_TOL`` of the nominal
  order. When the local slope is still changing as the errors reach round-off (the
  asymptotic regime starts below it), or it settles above the nominal order (the leading
  error term is too small to show), the order is *not measurable here*: said with the
  reason, exit status 0. Only a settled slope below the nominal order fails (exit 1).

Sizes are bounded up front (``_bounds``): the random states, the ladder's largest step
count, the scheme's stages. An order needs motion: a state that turns by less than
``MIN_MOTION`` radians over ``--t-end`` (a vanishing state, an equilibrium, a vanishing
time) is refused, since every error would sit at round-off and read as "exact".
"""

import argparse

import numpy as np

from ..core._errors import InputError
from . import _args, _bounds, _metadata, _problem, _signals

POISSON_TOL = 1e-12  # a Poisson map's defect is round-off: ~1e-16 per unit of |x|
ORDER_TOL = 0.3  # |measured - nominal order| allowed
ROUNDOFF = 200  # errors below ROUNDOFF eps |x| sqrt(n) are round-off dominated (~20 eps sqrt(n) measured at T = 10)
UPPER = 1e-4  # errors above UPPER |x| are pre-asymptotic
TAIL = 2.0  # the fit uses the usable step sizes within this factor of the smallest one
MIN_FIT_POINTS = 5  # distinct step counts the fit needs in that window (else: not measurable here)
PROBE = tuple(2**k for k in range(14))  # 1 .. 8192 steps
FINE_POINTS = len(PROBE)  # step counts over a factor 4 around the asymptotic window (the probe's shape):
# ~6 of them within the fit's factor TAIL = 2 (over a factor 8, as before, 4 or 5)
EXIT_FAILED = 1

EXAMPLES = """\
examples:
  jaxsplit check                                     # Lie-Trotter on the paper's symmetric body
  jaxsplit check --scheme kahan-li-6 --split casimir --inertia 3,2,1.5 --m0 0.2,0.9,0.3
  jaxsplit check --scheme strang --inertia 2,1,0.6667 --allow-nonphysical --json
  jaxsplit check --scheme blanes-moan-s6-prk --system attitude --inertia 3,2,1.5
  jaxsplit check --scheme strang --system heavy-top --inertia 2,1.5,1 --center-of-mass 0.1,0,0.5

exit status: 0 both checks pass (or the order is not measurable here: the reason is printed);
1 a check fails (defect above 1e-12 x |x|, or the measured order settles more than 0.3 below
the nominal one); 2 bad input.
"""


def add_parser(sub):
    p = sub.add_parser(
        "check", help="Poisson defect and measured order of a scheme on a system",
        description="Measure the Poisson defect (jacfwd, random states) and the convergence order (global "
                    "error ladder chosen for the scheme, log-log fit) of a scheme on a system.",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scheme", default="lie-trotter", help="any name from `jaxsplit schemes` (default lie-trotter)")
    _problem.add_split_arguments(p)
    _problem.add_system_arguments(p, state_help="initial state of the order measurement")
    p.add_argument("--reference", choices=("auto", "exact", "numerical"), default="auto",
                   help="reference of the order: exact (Jacobi elliptic; rigid-body, attitude) or numerical "
                        "(Kahan-Li 8, refined) (default auto: exact where it exists)")
    p.add_argument("--dt", type=_args.nonzero_float, default=0.1, metavar="H", help="step of the Poisson check (default 0.1)")
    p.add_argument("--states", type=_args.positive_int, default=32, metavar="N",
                   help="random states of the Poisson check (default 32)")
    p.add_argument("--seed", type=_args.seed, default=0, help="seed of the random states (default 0)")
    p.add_argument("--t-end", type=_args.positive_float, default=10.0, metavar="T",
                   help="time of the order measurement (default 10)")
    p.add_argument("--start", type=_args.positive_int, metavar="N",
                   help="smallest step count of a fixed ladder (12 counts over a factor 16; default: chosen by a probe)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=run)


MAX_COUNT = 2**17  # largest step count of a ladder (13 runs saving every step: 13 x 2^17 states ~ 40 MB)
LADDER_FACTOR = 16  # a --start ladder spans start .. 16 x start
MAX_STATES = 100_000  # the Poisson check takes jacfwd of every random state in one batch (~1 KiB each)
MIN_MOTION = 0.1  # radians the state must turn over --t-end for an order (or exactness) to be measurable


# --------------------------------------------------------------------------- the order


def _errors(step, x0, t_end, counts, reference):
    """(counts, step sizes, max-norm errors at t_end) for each step count, all ladders of a
    check through ONE compilation: every count runs as ``integrate(ts=[t_end])`` with a
    traced step count (its grid, then a partial step of round-off size), the counts padded
    to ``len(PROBE)`` and batched by ``vmap``."""
    import jax
    import jax.numpy as jnp

    from ..core._integrate import integrate
    from ..core._state import float_dtype, ravel

    counts = np.asarray(counts, dtype=np.int64)
    padded = np.concatenate([counts, np.full(max(0, len(PROBE) - len(counts)), counts[-1])])
    dtype = float_dtype(x0)
    hs = jnp.asarray(t_end / padded.astype(np.float64), dtype=dtype)
    at = jnp.full((1,), t_end, dtype=dtype)
    finals = jax.vmap(lambda h: ravel(integrate(step, x0, h, ts=at).final)[0])(hs)
    errs = np.max(np.abs(np.asarray(finals) - np.asarray(ravel(reference)[0])[None]), axis=1)
    return counts, np.asarray(hs)[:len(counts)], errs[:len(counts)].astype(np.float64)


class Window:
    """Which errors of a ladder lie between round-off and the pre-asymptotic regime."""

    def __init__(self, scale: float, eps: float, reference_accuracy: float):
        self.scale, self.eps, self.ref = scale, eps, reference_accuracy

    def floor(self, counts):
        return np.maximum(ROUNDOFF * self.eps * self.scale * np.sqrt(counts), 10 * self.ref)

    def usable(self, counts, errs):
        return np.isfinite(errs) & (errs > self.floor(counts)) & (errs < UPPER * self.scale)


def _slope(hs, errs, mask):
    return float(np.polyfit(np.log(hs[mask]), np.log(errs[mask]), 1)[0]) if mask.sum() >= 3 else None


def _fit(counts, hs, errs, window):
    """(order over the tail, order over the window before it, mask of the tail), or None when
    fewer than ``MIN_FIT_POINTS`` step counts lie in the tail (the asymptotic window)."""
    usable = window.usable(counts, errs)
    if not usable.any():
        return None
    h_min = hs[usable].min()
    tail = usable & (hs <= TAIL * h_min * (1 + 1e-12))
    if tail.sum() < MIN_FIT_POINTS:
        return None
    before = usable & (hs > TAIL * h_min * (1 + 1e-12)) & (hs <= TAIL**2 * h_min * (1 + 1e-12))
    return _slope(hs, errs, tail), _slope(hs, errs, before), tail


def _window_counts(counts, hs, errs, window):
    """The step counts in the fit's window (usable, within TAIL of the smallest usable h)."""
    usable = window.usable(counts, errs)
    if not usable.any():
        return counts[usable]
    return counts[usable & (hs <= TAIL * hs[usable].min() * (1 + 1e-12))]


def _fine(lo: int, hi: int):
    """``FINE_POINTS`` step counts from lo to hi, geometric (duplicates dropped)."""
    lo, hi = max(1, lo), min(MAX_COUNT, max(hi, lo + 1))
    return sorted({max(1, round(lo * (hi / lo) ** (k / (FINE_POINTS - 1)))) for k in range(FINE_POINTS)})


def measure_order(step, x0, t_end, reference, window, start=None):
    """Errors over a ladder chosen for the scheme (module docstring): a dict with the ladder,
    the errors, the fitted orders and the mask of the points used (``order`` None when no
    window exists, with ``note``)."""
    if start is not None:
        ladders = [_errors(step, x0, t_end, _ladder(start), reference)]
    else:
        counts, hs, errs = probe = _errors(step, x0, t_end, list(PROBE), reference)
        ladders = [probe]
        usable = window.usable(counts, errs)
        finite = np.isfinite(errs)
        if not usable.any() and finite.any() and np.all(errs[finite] <= window.floor(counts[finite])):
            return {"ladders": ladders, "order": None, "exact": True,
                    "note": f"all errors are at round-off (max {np.nanmax(errs):.1e}): the splitting is exact here, "
                            "so no order can be measured"}
        if usable.any():
            top = int(counts[usable].max())
            fine = _fine(top // 2, 2 * top)
        elif np.all(~finite | (errs >= UPPER * window.scale)):  # slow convergence: longer ladders
            more = _errors(step, x0, t_end, [2**k for k in range(14, 18)], reference)
            ladders.append(more)
            usable = window.usable(more[0], more[2])
            if not usable.any():
                return {"ladders": ladders, "order": None, "exact": False,
                        "note": f"the errors stay above {UPPER:g} x |x| up to {MAX_COUNT:,} steps (min "
                                f"{np.nanmin(more[2]):.1e}): give a shorter --t-end"}
            top = int(more[0][usable].max())
            fine = _fine(top // 2, 2 * top)
        else:  # from above the window to round-off within one doubling: resolve the jump
            above = counts[finite & (errs >= UPPER * window.scale)]
            lo = int(above.max()) if above.size else 1
            fine = _fine(lo, 2 * lo)
        ladders.append(_errors(step, x0, t_end, fine, reference))
    counts, hs, errs = _merged(ladders) if start is None else ladders[-1]
    fitted = _fit(counts, hs, errs, window)
    if fitted is None or fitted[0] is None:
        inside = _window_counts(counts, hs, errs, window)
        where = f" ({', '.join(map(str, inside))})" if inside.size else ""
        return {"ladders": ladders, "order": None, "exact": False,
                "note": f"only {inside.size} of the step counts {counts[0]}..{counts[-1]}{where} give errors between "
                        f"round-off and {UPPER:g} x |x| within a factor {TAIL:g} of the smallest such step size; the "
                        f"fit needs {MIN_FIT_POINTS} (errors {np.nanmin(errs):.1e} .. {np.nanmax(errs):.1e}): a "
                        "longer --t-end puts more step counts there"
                        + ("; or try another --start" if start is not None else "")}
    order, before, tail = fitted
    return {"ladders": ladders, "order": order, "order_before": before, "used": tail, "exact": False, "note": None}


def _ladder_text(ladders, start) -> str:
    """The step counts actually run, in words (the fine ladder has fewer than FINE_POINTS
    counts where they are small integers)."""
    def span(c):
        return f"{len(c)} step counts {c[0]}..{c[-1]}"

    if start is not None:
        return f"--start {start}: {span(ladders[0][0])} over a factor {LADDER_FACTOR}"
    parts = [f"probe {span(ladders[0][0])} (doubling)"]
    parts += [f"then {span(c)}" for c, _, _ in ladders[1:]]
    return ", ".join(parts) + (f"; the order is the slope over the counts with errors between round-off and "
                               f"{UPPER:g} x |x| within a factor {TAIL:g} of the smallest such step size "
                               f"(>= {MIN_FIT_POINTS} needed)")


def _merged(ladders):
    """Every (count, h, error) measured, by increasing count (the same run gives the same error)."""
    counts = np.concatenate([c for c, _, _ in ladders])
    keep = np.unique(counts, return_index=True)[1]
    return tuple(np.concatenate([part[k] for part in ladders])[keep] for k in range(3))


def _ladder(start):
    from ..checks._order import ladder

    return ladder(start, LADDER_FACTOR, 12)


def verdict(measured: dict, nominal: int):
    """("agrees" | "not measurable" | "disagrees", reason or None)."""
    p, before = measured["order"], measured.get("order_before")
    if p is None:
        return ("exact" if measured["exact"] else "not measurable"), measured["note"]
    if abs(p - nominal) <= ORDER_TOL:
        return "agrees", None
    if before is None or abs(p - before) > ORDER_TOL:
        trend = f" (slope {before:.2f} over the larger steps, {p:.2f} over the smallest)" if before is not None else ""
        return "not measurable", ("the local slope is still changing where the errors reach round-off" + trend
                                  + ": the asymptotic regime lies below round-off for this system and state")
    if p > nominal:
        return "not measurable", (f"the slope settles at {p:.2f}, above the nominal {nominal}: the order-{nominal} "
                                  "error term is too small to show above round-off for this system and state")
    return "disagrees", None


# --------------------------------------------------------------------------- references, states


def _reference(prob, x0, t_end, kind):
    """(reference state at t_end, description, its own error bound)."""
    import jax
    import jax.numpy as jnp

    if kind == "exact" and not prob.exact:
        raise InputError(f"--reference exact: the exact (Jacobi elliptic) solution is the free body's (--system "
                         f"rigid-body or attitude); --system {prob.name} has none: use --reference numerical")
    if prob.exact and kind != "numerical":
        from ._diagnostics import exact_states

        exact = exact_states(prob.system, x0, [t_end])  # padded rows: shares simulate's compilation
        return jax.tree_util.tree_map(lambda a: jnp.asarray(a[0]), exact), "exact (Jacobi elliptic)", 0.0
    from ..explore._sweep import reference_solution

    system = prob.system
    batch = jax.tree_util.tree_map(lambda a: np.asarray(a)[None], x0)
    ref, acc = reference_solution(batch, jax.tree_util.tree_map(lambda a: np.asarray(a)[None], system),
                                  t_end, system=_Same())
    return (jax.tree_util.tree_map(lambda a: jnp.asarray(a[0]), ref),
            "kahan-li-8 on the reference split, refined to agree with half its steps", float(acc[0]))


class _Same:
    """A family params -> system whose params are the system itself (one case)."""

    def __call__(self, params):
        return params

    def __hash__(self):
        return 0

    def __eq__(self, other):
        return isinstance(other, _Same)


def _random_states(prob, n, seed):
    """n random states of the system's kind: unit m (or |m0|-sized), a random attitude, unit Γ."""
    import jax.numpy as jnp

    from ..systems.so3 import quaternion_to_matrix

    rng = np.random.default_rng(seed)

    def unit(k, d=3):
        x = rng.standard_normal((k, d))
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    if prob.name == "rigid-body":
        return unit(n), jnp.asarray(unit(n))
    size = max(float(np.linalg.norm(prob.x0[0])), 1e-300)
    m = unit(n) * size
    other = np.asarray(quaternion_to_matrix(jnp.asarray(unit(n, 4)))) if prob.name == "attitude" else unit(n)
    return (m, other), (jnp.asarray(m), jnp.asarray(other))


def _scale(x0) -> float:
    import jax

    return float(max(np.max(np.abs(np.asarray(a))) for a in jax.tree_util.tree_leaves(x0))) or 1.0


def _check_motion(prob, t_end):
    """Refuse a run whose state hardly moves: |ẋ(0)| t_end / |x0| < MIN_MOTION."""
    import jax

    from ..core._state import ravel

    x0 = prob.state()
    # One compiled program: op by op, the generic Π(x) ∇H(x) compiled ~50 small ones (2 s).
    velocity = np.asarray(jax.jit(lambda system, x: ravel(system.vector_field(x))[0])(prob.system, x0))
    size = float(np.linalg.norm(np.asarray(ravel(x0)[0])))
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        turn = float(np.linalg.norm(velocity) * t_end / size) if size > 0 else 0.0
    if not turn >= MIN_MOTION:
        if prob.name == "rigid-body":  # exactly: m0 x I^-1 m0 = 0
            m0 = np.asarray(prob.x0)
            still = not np.any(np.cross(m0, m0 / np.asarray(prob.parameters["inertia"])))
        else:  # at round-off against the fastest turning the momentum alone allows
            m0 = np.asarray(prob.x0[0])
            scale = float(np.linalg.norm(m0)) * float(np.max(1 / np.asarray(prob.parameters["inertia"])))
            still = float(np.linalg.norm(velocity)) <= 1e-12 * max(scale, 1e-300) * max(size, 1e-300)
        if still:
            what = ("--m0 is an equilibrium of this body (m0 x I^-1 m0 = 0)" if prob.name == "rigid-body" else
                    f"the initial state is an equilibrium of --system {prob.name} (its vector field vanishes)")
        else:
            what = f"the state turns by only {turn:.2g} rad over --t-end {t_end:g}"
        raise InputError(f"{what}: no order can be measured (every error would be round-off); the check needs "
                         f">= {MIN_MOTION:g} rad: a longer --t-end, or an --m0 off the equilibria")


# --------------------------------------------------------------------------- run


def run(args):
    import jax
    import jax.numpy as jnp

    from ..checks._poisson import poisson_defect
    from ..systems._splitting import splitting

    prob = _problem.problem(args)
    method = _problem.scheme_and_split(args, prob)
    if prob.name == "rigid-body" and not np.any(prob.x0):
        raise InputError("--m0 must be non-zero (the order is measured on a moving state)")
    _check_motion(prob, args.t_end)
    _bounds.at_most(args.states, MAX_STATES, "--states", "the Poisson check takes jacfwd of all states in one batch")
    if args.start is not None:
        _bounds.at_most(args.start, MAX_COUNT // LADDER_FACTOR, "--start",
                        f"its ladder runs up to {LADDER_FACTOR} x --start steps, saving every step")
    from ..core._compose import Composition, roll

    step = splitting(prob.system, method.scheme, method.split, **method.options)
    step = roll(step) if isinstance(step, Composition) else step  # compiles in O(1) stages
    x0 = prob.state()
    reference, ref_kind, ref_acc = _reference(prob, x0, args.t_end, args.reference)

    # ---- Poisson defect over random states
    xs_np, xs = _random_states(prob, args.states, args.seed)
    defects = np.asarray(jax.jit(jax.vmap(lambda x: poisson_defect(step, prob.system, x, args.dt)))(xs))
    worst = int(np.argmax(defects))
    scale = _scale(x0)
    poisson_tol = POISSON_TOL * max(1.0, scale)
    poisson_ok = bool(defects[worst] <= poisson_tol)

    # ---- measured order
    eps = float(jnp.finfo(jnp.float64).eps)
    measured = measure_order(step, x0, args.t_end, reference, Window(scale, eps, ref_acc), args.start)
    state, reason = verdict(measured, method.scheme.order)
    counts, hs, errs = _merged(measured["ladders"]) if args.start is None else measured["ladders"][-1]
    used = measured.get("used")
    worst_state = jax.tree_util.tree_map(lambda a: np.asarray(a)[worst], xs_np)
    result = {
        "system": prob.name, **prob.parameters,
        "scheme": method.scheme.name, "nominal_order": method.scheme.order, "split": method.split,
        "split_chosen": method.chosen, "shift_axis": method.shift_label,
        "poisson_defect_max": float(defects[worst]), "poisson_defect_median": float(np.median(defects)),
        "poisson_worst_state": worst_state, "poisson_dt": args.dt, "poisson_states": args.states,
        "poisson_tolerance": poisson_tol, "poisson_ok": poisson_ok,
        "measured_order": measured["order"],
        "measured_order_larger_steps": measured.get("order_before"),
        "order_points_used": None if used is None else int(used.sum()),
        "order_verdict": state, "order_ok": state != "disagrees", "order_note": reason,
        "t_end": args.t_end, "step_counts": counts, "step_sizes": hs, "errors": errs,
        "used": used, "probe": None if args.start is not None else {"step_counts": measured["ladders"][0][0],
                                                                    "errors": measured["ladders"][0][2]},
        "reference": ref_kind, "reference_accuracy": ref_acc, "ladder": _ladder_text(measured["ladders"], args.start),
    }
    with _signals.current().critical():  # the measurements are done: print them whole
        _print(args, result)
    return 0 if (poisson_ok and state != "disagrees") else EXIT_FAILED


def _print(args, r):
    if args.json:
        _metadata.print_json(r)
        return
    split = r["split"] + (f" (shift axis {r['shift_axis']})" if r["shift_axis"] is not None else "")
    chosen = " (chosen for the scheme)" if r["split_chosen"] else ""
    print(f"jaxsplit check: {r['scheme']} (nominal order {r['nominal_order']}), {split} split{chosen}, "
          f"{r['system']} I = ({_problem.fmt_vec(r['inertia'])})")
    print(f"  Poisson defect, h = {r['poisson_dt']:g}, {r['poisson_states']} random states: max "
          f"{r['poisson_defect_max']:.2e} (median {r['poisson_defect_median']:.2e}) -> "
          f"{'Poisson to round-off' if r['poisson_ok'] else 'NOT Poisson'} (tolerance {r['poisson_tolerance']:.1g})")
    counts, p = r["step_counts"], r["measured_order"]
    if p is not None:
        used = np.asarray(counts)[np.asarray(r["used"])]
        word = {"agrees": "agrees", "disagrees": "DISAGREES", "not measurable": "not measurable here"}[r["order_verdict"]]
        hs_used = np.asarray(r["step_sizes"])[np.asarray(r["used"])]
        print(f"  measured order {p:.3f} from {r['order_points_used']} step counts ({used.min()}..{used.max()}, "
              f"h = {hs_used.max():.3g}..{hs_used.min():.3g}) to t = {r['t_end']:g} -> {word} (tolerance {ORDER_TOL})")
    print(f"  ladder: {r['ladder']}")
    if r["order_note"]:
        print(f"  order {'not measurable here' if r['order_verdict'] != 'exact' else 'not measured'}: "
              f"{r['order_note']}")
    print(f"  reference: {r['reference']}" + (f", accuracy {r['reference_accuracy']:.1e}"
                                               if r["reference_accuracy"] else ""))
