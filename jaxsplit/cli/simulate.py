"""``jaxsplit simulate``: integrate a system, save the trajectory and a figure.

Systems (``--system``, ``_problem``): the free rigid body (default), the free body with its
attitude (m, Q), the heavy top and the gravity-gradient satellite (m, Γ). With no
arguments: the seed paper's symmetric body I = (2, 2, 1) from m0 = (0.6, 0, 0.8) with
Lie–Trotter, h = 0.01, 10 000 steps. The summary gives every invariant's largest error
over the saved states (``_diagnostics``: the energy, the Casimirs, and the attitude's |m|²,
Q m and QᵀQ) and, for the free body, the distance to the exact (Jacobi elliptic) solution.

``--save-at`` asks for the states at given times: partial steps of the scheme from the grid
(``integrate(ts=...)``), computed in the chunk that holds them; they become the rows of the
trajectory file (``_data``: the format ``fit`` reads). ``--dtype float32`` runs in single
precision (diagnostics in float64) and says how the Casimir drifts; ``--renormalize``
projects the norms back after every step (a projection, reported as such). ``--noise``
adds Gaussian noise to the written states: synthetic observations for ``fit``. Outputs go
to a new, uniquely named pair ``jaxsplit-runs/simulate-<UTC time>-<scheme>.npz`` / ``.png``
unless ``--out`` names them or ``--no-save`` is given.
"""

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..core._errors import InputError
from . import (
    _args,
    _bounds,
    _chunked,
    _data,
    _diagnostics,
    _io,
    _metadata,
    _problem,
    _progress,
    _signals,
    _spin_simulate,
)

EXIT_OK = 0
EXIT_NONFINITE = 3
DEFAULT_DT = 0.01
DEFAULT_STEPS = 10_000
RUNS_DIR = "jaxsplit-runs"
FORMATS = _data.FORMATS
DENSE_POINTS = 4000  # partial steps drawn when the saved states are too sparse to join
# float32 drift of the Casimir without a projection, measured (see the README's command line section):
# jaxsplit simulate --dtype float32 --scheme kahan-li-6 --dt 0.01 --steps 1e5 [--inertia 3,2,1.5 --m0 0.2,0.9,0.3]
FLOAT32_DRIFT = ("Kahan-Li 6, 2*10^4 steps on I = (3, 2, 1.5): |m| drifts by more than 1e-5 relative, "
                 "tests/test_cli_systems.py; the projection restores the norms, not accuracy")

EXAMPLES = """\
examples:
  jaxsplit simulate                                   # the paper's symmetric body, Lie-Trotter
  jaxsplit simulate --scheme strang --dt 0.05 --t-end 500 --out run.npz
  jaxsplit simulate --inertia 3,2,1.5 --m0 0.2,0.9,0.3 --scheme kahan-li-6 \\
                    --split casimir --steps 1e6 --save-every 100 --out asym.csv
  jaxsplit simulate --system heavy-top --center-of-mass 0,0,0.5 --weight 1 --gamma0 0,0.6,0.8 \\
                    --m0 0,0.4,3 --scheme strang --t-end 20 --out top.npz
  jaxsplit simulate --system attitude --q0 1,0,0,0 --scheme kahan-li-6 --t-end 50
  jaxsplit simulate --system gravity-gradient --rate 0.5 --gamma0 1,0,0 --m0 0.1,0.2,1
  jaxsplit simulate --save-at 0.5,1,2.5 --out obs.csv  # states at those times (partial steps)
  jaxsplit simulate --save-at 0.5,1,1.5,2,2.5,3 --noise 1e-3 --seed 1 --out obs.npz  # observations for fit
  jaxsplit simulate --dtype float32 --renormalize --scheme kahan-li-6 --steps 1e5
  jaxsplit simulate --json --no-save                  # one JSON object, no files
  jaxsplit simulate --dt -0.01 --steps 100            # backwards in time
  jaxsplit simulate --system spin-lattice --lattice square --size 64x64 --exchange 1 --field 0,0,0.1 \
                    --dt 0.1 --steps 2000 --save-every 2 --out square.npz   # spin waves: S(q,w) figure

--save-at @FILE reads the times from FILE, one per line.

outputs: --out PATH writes PATH (.npz, or .csv by suffix or --format): t, step, the state
(m; Q or gamma), the scalar invariants and the exact solution per saved state, with
metadata (every input, versions, dtype); `jaxsplit fit --data PATH` reads it as it is. A
figure goes next to it (PATH with suffix .png; --figure moves it, --no-figure drops it).
Without --out the pair goes to a new file in ./jaxsplit-runs/ and its name is printed;
--no-save writes nothing. Existing files are never overwritten without --force. Negative
numbers may be given directly (--m0 -0.6,0,0.8).
"""


def add_parser(sub):
    p = sub.add_parser(
        "simulate", help="integrate a system; save trajectory, figure, summary",
        description="Integrate a rigid body (free, with its attitude, heavy top, gravity gradient) with a "
                    "splitting scheme and report every invariant's error (and the error against the exact "
                    "solution for the free body).",
        epilog=EXAMPLES + "\n" + _args.EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("problem")
    _problem.add_system_arguments(g)
    _spin_simulate.add_arguments(p, g)
    g = p.add_argument_group("method")
    g.add_argument("--scheme", default=None, help="any name from `jaxsplit schemes` (default lie-trotter)")
    _problem.add_split_arguments(g)
    g.add_argument("--dt", type=_args.nonzero_float, default=None, metavar="H",
                   help=f"step size, non-zero; negative runs backwards (default {DEFAULT_DT})")
    n = g.add_mutually_exclusive_group()
    n.add_argument("--steps", type=_args.positive_int, metavar="N",
                   help=f"number of steps (default {DEFAULT_STEPS:,}, or up to the last --save-at time)")
    n.add_argument("--t-end", type=_args.positive_float, metavar="T",
                   help="duration; steps = round(T / |H|)")
    g.add_argument("--tol", type=_args.positive_float, metavar="TOL",
                   help="choose the scheme, split and step that reach max-norm error TOL at --t-end (default "
                        f"{DEFAULT_STEPS * DEFAULT_DT:g}) at the least modelled cost (jaxsplit.auto_splitting); "
                        "excludes --scheme, --split, --shift-axis, --dt, --steps")
    g.add_argument("--dtype", choices=("float64", "float32"), default="float64",
                   help="precision of the integration (diagnostics are computed in float64; default float64)")
    g.add_argument("--renormalize", action="store_true",
                   help="after every step, project the norms back to their initial values (|m| of the free body, "
                        "the rows of Q, |Gamma|): a projection, not part of the scheme, reported as such")
    g = p.add_argument_group("output")
    g.add_argument("--save-every", type=_args.positive_int, default=1, metavar="K",
                   help="keep every K-th state (and the last one); the reported errors are maxima over "
                        "the kept states (default 1)")
    g.add_argument("--save-at", type=_args.times("--save-at"), metavar="T1,T2,...|@FILE",
                   help="also compute the states at these times (partial steps of the scheme, any times within the "
                        "run; @FILE: one time per line); they become the rows of the trajectory file")
    g.add_argument("--reference", choices=("auto", "exact", "none"), default="auto",
                   help="exact: the distance to the exact (Jacobi elliptic) solution, for the free body "
                        "(rigid-body, attitude); none: skip it (default auto: exact where it exists)")
    g.add_argument("--noise", type=_args.nonnegative_float, default=0.0, metavar="SIGMA",
                   help="add N(0, SIGMA^2) noise to the written states (synthetic observations; the summary is "
                        "of the computed states) (default 0)")
    g.add_argument("--seed", type=_args.seed, default=0, help="seed of --noise (default 0)")
    g.add_argument("--out", metavar="PATH", help="trajectory file (.npz or .csv)")
    g.add_argument("--format", choices=FORMATS, help="trajectory format (default: from the suffix of --out, else npz)")
    g.add_argument("--figure", metavar="PNG", help="figure path (default: --out with suffix .png)")
    g.add_argument("--no-figure", action="store_true", help="do not draw the figure")
    g.add_argument("--no-save", action="store_true", help="write no files; print the summary only")
    g.add_argument("--max-memory", type=_args.byte_size, metavar="SIZE",
                   help="refuse runs whose saved states need more (default: half the available memory)")
    _args.add_common_flags(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- planning


def _note(text: str) -> None:
    print(f"jaxsplit: note: {text}", file=sys.stderr)


def _steps(args, at) -> int:
    """The step count, bounded: --steps, --t-end / --dt without overflow, else up to the last
    --save-at time (rounded up to a whole step), else the default."""
    if args.t_end is None:
        if args.steps is None and at is not None:
            steps = float(np.max(np.abs(at))) / abs(args.dt)
            if not steps < _bounds.MAX_STEPS + 0.5:
                raise InputError(f"--save-at {np.max(np.abs(at)):g} / --dt {abs(args.dt):g} is {steps:.3g} steps, more "
                                 f"than the {_bounds.MAX_STEPS:,} allowed (step indices exact in float64)")
            nearest = round(steps)
            return max(1, nearest if abs(steps - nearest) <= 1e-9 * max(1.0, steps) else math.ceil(steps))
        n = args.steps or DEFAULT_STEPS
        return _bounds.at_most(n, _bounds.MAX_STEPS, "--steps", "step indices exact in float64")
    notes = []
    n = _bounds.step_count(args.t_end, args.dt, notes=notes)
    for note in notes:
        _note(note)
    return n


def _save_at(at, n_steps: int, dt: float):
    """The --save-at times sorted along the run, each within it (from t = 0 to n_steps * dt)."""
    if at is None:
        return None
    at = np.asarray(at, dtype=np.float64)
    along = at * np.sign(dt)  # distance travelled along the run
    end = n_steps * abs(dt)
    if np.any(along < 0):
        bad = at[np.argmin(along)]
        raise InputError(f"--save-at {bad:g} is before the start of the run (t = 0"
                         + (", integrating backwards: times must be <= 0" if dt < 0 else "") + ")")
    if np.any(along > end * (1 + 1e-12)):
        bad = at[np.argmax(along)]
        raise InputError(f"--save-at {bad:g} is after the end of the run (t = {n_steps * dt:g}: {n_steps:,} steps of "
                         f"--dt {dt:g}); give a longer --t-end, or leave out --steps/--t-end to end at the last time")
    return at[np.argsort(along, kind="stable")]


def _output_paths(args, outputs, when: str):
    """(trajectory path, format, figure path or None), claimed before running."""
    if args.no_save:
        if args.out or args.figure:
            raise InputError("--no-save contradicts --out/--figure")
        return None, None, None
    if args.out is None:
        if args.figure:
            return None, None, outputs.file(args.figure, "figure")
        return _default_outputs(args, outputs, when)
    out = Path(args.out).expanduser()
    if args.out.endswith(("/", os.sep)) or os.path.isdir(_io.resolve(args.out, "--out")):
        raise InputError(f"--out {args.out!r} is a directory; give a file name such as "
                         f"{os.path.join(args.out, 'run.npz')!r}")
    suffix = out.suffix.lower().lstrip(".")
    if suffix in FORMATS:
        fmt = suffix
        if args.format and args.format != fmt:
            raise InputError(f"--format {args.format} conflicts with the suffix of --out {args.out!r}")
    elif suffix == "" or out.name.endswith("."):
        fmt = args.format or "npz"
        out = out.with_name(out.name.rstrip(".") + "." + fmt)
    elif args.format:
        fmt = args.format
    else:
        raise InputError(f"--out {args.out!r}: suffix must be .npz or .csv (or give --format npz|csv)")
    out = outputs.file(out, "trajectory")
    figure = None
    if not args.no_figure:
        figure = outputs.file(args.figure or out.with_suffix(".png"), "figure")
    return out, fmt, figure


def _default_outputs(args, outputs, when: str):
    """A fresh pair in ./jaxsplit-runs/ (created); none when the directory is not writable."""
    fmt = args.format or "npz"
    base = Path(RUNS_DIR)
    try:
        base.mkdir(exist_ok=True)
        stem = f"simulate-{when}-{args.scheme}"
        for k in range(1, 10_000):
            out = base / f"{stem if k == 1 else f'{stem}-{k}'}.{fmt}"
            figure = None if args.no_figure else out.with_suffix(".png")
            if out.exists() or (figure is not None and figure.exists()):
                continue
            try:
                out = outputs.file(out, "trajectory", force=False)
                figure = None if figure is None else outputs.file(figure, "figure", force=False)
                return out, fmt, figure
            except _io.OutputBusy:  # a run started in the same second holds this name
                continue
        raise InputError("no free file name")
    except (OSError, InputError) as err:
        reason = err.strerror if isinstance(err, OSError) else str(err)
        _note(f"cannot write to ./{RUNS_DIR} ({reason}); no files written (give --out PATH)")
        return None, None, None


def _bytes_per_saved(prob) -> int:
    """Memory per saved state: t, step, the state, its exact value and the invariants, twice."""
    import jax

    size = sum(np.size(a) for a in jax.tree_util.tree_leaves(prob.x0))
    invariants = sum(np.size(f(prob.state())) for f in prob.system.invariants().values())
    return 2 * 8 * (2 + 2 * size + invariants)


def run(args):
    if args.system == "spin-lattice" or any(getattr(args, d, None) is not None for d in _spin_simulate.OWN):
        return _spin_simulate.run(args)
    with _io.Outputs(force=args.force) as outputs:
        return _run(args, outputs)


class _Plan(NamedTuple):
    """Everything decided before the run: validated, bounded and claimed."""

    problem: _problem.Problem
    method: _problem.Method
    exact: bool
    n_steps: int
    save_every: int
    at: np.ndarray | None
    out: Path | None
    fmt: str | None
    figure: Path | None
    auto: object = None  # what --tol chose (jaxsplit.auto_splitting)


def _auto(args, prob):
    """--tol: (method, step size, step count, the library's choice) from ``jaxsplit.auto_splitting``."""
    given = [flag for flag, value in (("--scheme", args.scheme), ("--split", args.split),
                                      ("--shift-axis", args.shift_axis), ("--dt", args.dt), ("--steps", args.steps))
             if value is not None]
    if given:
        raise InputError(f"--tol chooses the scheme, the split and the step: drop {', '.join(given)} (give --t-end)")
    import jaxsplit

    t_end = args.t_end if args.t_end is not None else (
        float(np.max(np.abs(args.save_at))) if args.save_at is not None else DEFAULT_STEPS * DEFAULT_DT)
    choice = jaxsplit.auto_splitting(prob.system, prob.state(), tol=args.tol, t_end=t_end)
    n_steps = _bounds.at_most(int(choice.n_steps), _bounds.MAX_STEPS, "the step count --tol chose",
                              "step indices exact in float64", "give a larger --tol or a shorter --t-end")
    method = _problem.Method(_bounds.scheme(choice.scheme), choice.split, dict(choice.options), True)
    return method, float(choice.h), n_steps, choice


def _plan(args, outputs) -> _Plan:
    prob = _problem.problem(args)
    if args.reference == "exact" and not prob.exact:
        raise InputError(f"--reference exact: the exact (Jacobi elliptic) solution is the free body's (--system "
                         f"rigid-body or attitude); --system {prob.name} has none")
    auto = None
    if args.tol is not None:
        method, args.dt, n_steps, auto = _auto(args, prob)
    else:
        args.scheme = "lie-trotter" if args.scheme is None else args.scheme
        args.dt = DEFAULT_DT if args.dt is None else args.dt
        method = _problem.scheme_and_split(args, prob)
        n_steps = _steps(args, args.save_at)
    at = _save_at(args.save_at, n_steps, args.dt)
    save_every = _bounds.at_most(args.save_every, _bounds.MAX_STEPS, "--save-every", "step indices exact in float64")
    _bounds.saved_states(n_steps, save_every, _bytes_per_saved(prob), _bounds.memory_limit(args.max_memory),
                         extra=0 if at is None else len(at))
    writes = "when files are written (not with --no-save)"
    _args.refuse_unused(args, {"noise": (not args.no_save, "to the written trajectory, and --no-save writes none"),
                               "seed": (args.noise > 0, "with --noise SIGMA > 0 (it seeds the noise)"),
                               "figure": (not args.no_figure, "without --no-figure"),
                               "format": (not args.no_save, writes), "force": (not args.no_save, writes),
                               "no_figure": (not args.no_save, writes)})
    when = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out, fmt, figure = _output_paths(args, outputs, when)
    if args.dtype == "float32":
        _note("float32 run: round-off drifts the norms a splitting keeps exactly (" + FLOAT32_DRIFT + "); "
              + ("--renormalize projects them back after every step (a projection, not part of "
                                   "the scheme)" if args.renormalize else "--renormalize projects them back")
              + "; the summary measures the drift in float64")
    return _Plan(prob, method, prob.exact and args.reference != "none", n_steps, save_every, at, out, fmt, figure,
                 auto)


# --------------------------------------------------------------------------- run


def _step(plan, args):
    import jax.numpy as jnp

    from ..core._flows import Renormalized
    from ..systems._splitting import splitting

    m = plan.method
    step = splitting(plan.problem.system, m.scheme, m.split, **m.options)
    if args.renormalize:
        dtype = jnp.dtype(args.dtype)
        norms = plan.problem.norms
        norms = (tuple(None if n is None else jnp.asarray(n, dtype) for n in norms) if isinstance(norms, tuple)
                 else jnp.asarray(norms, dtype))
        step = Renormalized(step, norms)
    return step


def _run(args, outputs):
    plan = _plan(args, outputs)  # everything checked before any work
    stop = _signals.current()
    step = _step(plan, args)
    progress = _progress.Progress(plan.n_steps, enabled=not args.quiet)
    with stop.defer():  # a signal stops the run after the current chunk
        flows = getattr(getattr(step, "step", step), "flows_per_step", 1)
        result = _chunked.run_chunked(step, plan.problem.state(args.dtype), args.dt, plan.n_steps, plan.save_every,
                                      flows_per_step=flows, progress=progress, stop=lambda: stop.requested,
                                      at=plan.at)
    with stop.critical():  # from here on a signal only changes the exit status: the outputs complete
        return _report(args, outputs, plan, result, step)


def _parts(prob, states) -> dict:
    """{part name: array (n, ...)} of saved states (float64)."""
    leaves = states if isinstance(states, tuple) else (states,)
    return {name: np.asarray(a, dtype=np.float64) for name, a in zip(prob.parts, leaves)}


def _diagnose(plan, t, states):
    """Invariant errors (and the distance to the exact solution) per state."""
    prob = plan.problem
    values = _diagnostics.invariant_values(prob.system, states)
    errors = _diagnostics.relative_errors(values)
    exact = exact_error = None
    if plan.exact:
        exact = _diagnostics.exact_states(prob.system, prob.x0, t)
        exact_error = _diagnostics.state_errors(states, exact)
    return values, errors, exact, exact_error


def _report(args, outputs, plan, result, step):
    """Diagnostics, files and summary of a finished or stopped run (never lose work)."""
    prob, method = plan.problem, plan.method
    t_grid = result.steps * args.dt
    n_grid = len(t_grid)
    at = plan.at is not None
    t_all = np.concatenate([t_grid, result.t_at]) if at else t_grid
    states = _chunked.concatenate([result.x, result.x_at]) if at else result.x
    values, errors, exact, exact_error = _diagnose(plan, t_all, states)
    status = "ok" if result.nonfinite_step is None and not result.interrupted else (
        "nonfinite" if result.nonfinite_step is not None else "interrupted")
    maxima = {label: float(np.max(e)) for label, e in errors.items()}
    casimirs = list(prob.system.casimirs())
    projection = None
    if args.renormalize:
        projection = {"rigid-body": "|m| restored after every step", "attitude": "|m| and the unit rows of Q restored "
                      "after every step"}.get(prob.name, "|Gamma| restored after every step")
    summary = {
        "system": prob.name, **prob.parameters,
        "scheme": method.scheme.name, "order": method.scheme.order, "split": method.split,
        "shift_axis": method.shift_label, "dt": args.dt,
        "steps": result.completed, "steps_requested": plan.n_steps, "t_end": result.completed * args.dt,
        "save_every": plan.save_every, "saved_states": n_grid,
        "save_at": None if not at else len(plan.at), "states_at_times": None if not at else len(result.t_at),
        "invariant_errors": maxima,
        "energy_error_max": maxima["energy"],
        "casimir_error_max": max((maxima[c] for c in casimirs), default=None),
        "exact_error_max": None if exact_error is None else float(np.max(exact_error)),
        "reference": "exact (Jacobi elliptic)" if plan.exact else None,
        "seconds": result.seconds,
        "steps_per_second": result.completed / result.seconds if result.seconds > 0 else None,
        "status": status, "nonfinite_step": result.nonfinite_step,
        "dtype": args.dtype, "projection": projection, "noise": args.noise or None,
        "tol": args.tol, "predicted_error": None if plan.auto is None else float(plan.auto.predicted_error),
    }

    # ---- outputs (also, and especially, for a stopped run: never lose work)
    written = {}
    if plan.out is not None:
        rows = slice(n_grid, None) if at else slice(0, n_grid)
        arrays = {"t": t_all[rows]} | ({} if at else {"step": result.steps})
        observed = _parts(prob, _chunked.rows(states, rows))
        if args.noise > 0:
            rng = np.random.default_rng(args.seed)
            observed = {k: v + args.noise * rng.standard_normal(v.shape) for k, v in observed.items()}
        arrays |= observed
        arrays |= {_diagnostics.column_name(k): v[rows] for k, v in values.items() if v.ndim == 1}
        if exact is not None:
            arrays |= {f"{k}_exact": v for k, v in _parts(prob, _chunked.rows(exact, rows)).items()}
        meta = _metadata.run_metadata("simulate") | prob.parameters | {
            k: summary[k] for k in ("scheme", "order", "split", "shift_axis", "dt", "steps_requested", "save_every",
                                    "status", "nonfinite_step", "dtype", "projection", "reference", "tol",
                                    "predicted_error")
        } | {"steps_completed": result.completed, "allow_nonphysical": args.allow_nonphysical,
             "rows": "the --save-at times (partial steps)" if at else "every --save-every-th step",
             "noise": args.noise, "seed": args.seed if args.noise > 0 else None}
        _data.write(outputs, plan.out, plan.fmt, arrays, meta)
        written["trajectory"] = str(plan.out)
    if plan.figure is not None:
        with np.errstate(over="ignore", invalid="ignore"):  # a blown-up run: draw its finite part
            fig = _figure(args, plan, result, step, t_all, states, errors, exact_error, maxima, status)
        from . import _figures

        outputs.write(plan.figure, lambda f: _figures.save_figure(fig, f))
        written["figure"] = str(plan.figure)
    summary["outputs"] = written

    if args.json:
        _metadata.print_json(summary)
    else:
        _print_summary(summary, prob)
    if result.nonfinite_step is not None:
        k = result.nonfinite_step
        print(f"jaxsplit: error: the state became non-finite at step {k:,} (t = {k * args.dt:g}); "
              f"kept the {result.completed:,} steps before it" + (" (written)" if written else ""),
              file=sys.stderr)
        return EXIT_NONFINITE
    if result.interrupted:
        print(f"jaxsplit: interrupted ({_signals.current().signal_name}) after {result.completed:,} of "
              f"{plan.n_steps:,} steps; kept what was computed" + (" (written)" if written else ""), file=sys.stderr)
        return _signals.EXIT_INTERRUPTED
    return EXIT_OK


# --------------------------------------------------------------------------- figure


def _levels(prob):
    """The function whose level curves are drawn on each sphere (None: no levels)."""
    p = prob.parameters
    inertia = np.asarray(p["inertia"])
    if prob.name == "heavy-top":
        chi = p["weight"] * np.asarray(p["center_of_mass"])
        return lambda g: g @ chi, "potential level curves"
    if prob.name == "gravity-gradient":
        return lambda g: 1.5 * p["rate"] ** 2 * np.sum(g * inertia * g, axis=-1), "potential level curves"
    return lambda m: 0.5 * np.sum(m * m / inertia, axis=-1), "energy level curves"


def _dense(plan, step, states, t_end, dt, dtype):
    """States from partial steps over the start of the run, close enough together to be
    joined (spacing ~ CHORD/2 at the fastest speed of the saved states), at most
    ``DENSE_POINTS``: (states, the time span covered)."""
    import jax
    import jax.numpy as jnp

    from ..core._integrate import integrate
    from ._figures import CHORD

    x64 = jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float64), states)
    speed = jax.jit(jax.vmap(plan.problem.system.vector_field))(x64)

    def rate(v, x):
        size = np.maximum(np.linalg.norm(np.asarray(x).reshape(len(x), -1), axis=1), 1e-300)
        return np.max(np.linalg.norm(np.asarray(v).reshape(len(v), -1), axis=1) / size)

    fastest = max(jax.tree_util.tree_leaves(jax.tree_util.tree_map(rate, speed, x64)))
    span = min(abs(t_end), DENSE_POINTS * 0.5 * CHORD / max(float(fastest), 1e-300))
    times = np.linspace(0.0, span, DENSE_POINTS) * (1.0 if dt > 0 else -1.0)
    return _chunked.host(integrate(step, plan.problem.state(dtype), dt, ts=times).x), span


def _figure(args, plan, result, step, t_all, states, errors, exact_error, maxima, status):
    from . import _figures

    prob = plan.problem
    order = np.argsort(t_all * np.sign(args.dt), kind="stable")
    n_grid = len(result.steps)
    grid = _parts(prob, result.x)
    at = _parts(prob, result.x_at) if plan.at is not None else None
    stride = max(1, int(np.ceil(n_grid / _figures._MAX_POINTS)))
    drawn = {k: v[::stride] if stride > 1 else v for k, v in grid.items()}
    if stride > 1:  # keep the last state
        drawn = {k: np.concatenate([v, grid[k][-1:]]) for k, v in drawn.items()}
    dense, dense_note = None, ""
    spheres_of = {"m": (None,), "Q": (0, 1, 2), "gamma": (None,)}
    radius_m = float(np.linalg.norm(grid["m"][0])) or 1.0
    sparse = any(_figures.sparse(_columns(drawn[k], c), 1.0 if k != "m" else radius_m)
                 for k in prob.parts if k != "m" or prob.name in ("rigid-body", "attitude") for c in spheres_of[k])
    if sparse and result.completed > 0:
        x_dense, span = _dense(plan, step, result.x, result.completed * args.dt, args.dt, args.dtype)
        dense = _parts(prob, x_dense)
        dense_note = f"\nline: partial steps for |t| <= {span:.4g}; dots: saved states"
    levels, level_label = _levels(prob)

    def curve(part, column, label, color):
        pick = lambda d: None if d is None else _columns(d[part], column)
        return _figures.Curve(_columns(drawn[part], column), label, color, pick(dense), pick(at))

    spheres = []
    inertia = prob.parameters["inertia"]
    if prob.name in ("rigid-body", "attitude"):
        spheres.append(_figures.Sphere(f"m on the sphere |m| = {radius_m:.4g} (body frame){dense_note}",
                                       [curve("m", None, "m(t)", "tab:blue")], radius_m, levels, level_label,
                                       ("m1", "m2", "m3")))
    if prob.name == "attitude":
        q0, m0 = prob.x0[1], prob.x0[0]
        spheres.append(_figures.Sphere(f"body axes in space (the columns of Q){dense_note}",
                                       [curve("Q", k, f"body axis {k + 1}", c) for k, c in
                                        enumerate(("tab:red", "tab:green", "tab:blue"))], 1.0, None, "",
                                       ("x", "y", "z"), (("L = Q m (fixed)", q0 @ m0),) if np.any(m0) else ()))
    if prob.name in ("heavy-top", "gravity-gradient"):
        what = "upward vertical" if prob.name == "heavy-top" else "direction to the planet"
        marks = ()
        if prob.name == "heavy-top" and np.any(prob.parameters["center_of_mass"]):
            marks = (("centre of mass direction", np.asarray(prob.parameters["center_of_mass"])),)
        spheres.append(_figures.Sphere(f"Gamma on the unit sphere (body frame){dense_note}",
                                       [curve("gamma", None, f"Gamma(t), the {what}", "tab:blue")], 1.0, levels, level_label,
                                       ("e1", "e2", "e3"), marks))
    labels = {"energy": "energy", **{k: k for k in errors if k != "energy"}}
    groups = [("energy error\n|H/H0 - 1|", {"energy": errors["energy"][order]})]
    others = {labels[k]: errors[k][order] for k in errors if k != "energy"}
    if others:
        groups.append(("Casimirs" + (" and first integrals" if len(others) > len(prob.system.casimirs()) else "")
                       + "\nrelative error", others))
    shown_max = dict(maxima)
    if exact_error is not None:
        groups.append(("distance to exact\nmax|x - x_exact|", {"exact solution": exact_error[order]}))
        shown_max["exact solution"] = float(np.max(exact_error))
    m = plan.method
    params = ", ".join(f"{k.replace('_', ' ')} {_problem.fmt_value(v)}" for k, v in prob.parameters.items()
                       if k not in ("system", "inertia", "m0"))
    title = (f"{prob.name}: {m.scheme.name} ({m.split} split), I = ({_problem.fmt_vec(inertia)}), "
             f"m0 = ({_problem.fmt_vec(prob.parameters['m0'])})" + (f", {params}" if params else "")
             + f"\nh = {args.dt:g}, {result.completed:,} steps, {args.dtype}"
             + (", renormalized" if args.renormalize else "") + ("" if status == "ok" else f" [{status}]"))
    return _figures.simulate_figure(t_all[order], spheres, groups, shown_max, title=title)


def _columns(a, column):
    """Points (n, 3): a vector part, or column ``column`` of a matrix part (Q e_k: body axis k in space)."""
    return a if column is None else a[:, :, column]


# --------------------------------------------------------------------------- summary


def _print_summary(s, prob):
    split = s["split"] + (f" (shift axis {s['shift_axis']})" if s["shift_axis"] is not None else "")
    print(f"jaxsplit simulate: {s['scheme']} (order {s['order']}), {split} split, h = {s['dt']:g}, "
          f"{s['steps']:,} steps to t = {s['t_end']:g}" + ("" if s["dtype"] == "float64" else f", {s['dtype']}"))
    params = "; ".join(f"{k.replace('_', ' ')} = {_problem.fmt_value(v)}" for k, v in prob.parameters.items()
                       if k != "system")
    print(f"  {prob.name}: {params}")
    if s["tol"] is not None:
        print(f"  --tol {s['tol']:g}: scheme, split and step chosen by jaxsplit.auto_splitting (predicted max error "
              f"{s['predicted_error']:.2e} at t = {s['t_end']:g})")
    every = "" if s["save_every"] == 1 else f", every {s['save_every']:,}th step"
    at = f" and the {s['states_at_times']:,} states at --save-at times" if s["save_at"] else ""
    print(f"  over the {s['saved_states']:,} saved states{every}{at}:")
    for label, value in s["invariant_errors"].items():
        print(f"  max relative {label} error".ljust(38) + f"{value:.3e}")
    if s["exact_error_max"] is not None:
        print("  max error vs exact solution".ljust(38) + f"{s['exact_error_max']:.3e}   max|x - x_exact| "
              "(Jacobi elliptic)")
    if s["projection"]:
        print(f"  projection applied: {s['projection']} (--renormalize; not part of the scheme)")
    rate = s["steps_per_second"]
    print(f"  {s['steps']:,} steps in {s['seconds']:.2f} s" + (f" ({rate:,.0f} steps/s, compilation included)"
                                                              if rate and math.isfinite(rate) else ""))
    outs = s["outputs"]
    if outs:
        print("  wrote " + ", ".join(f"{k} {v}" for k, v in outs.items()))
    else:
        print("  no files written (--out PATH saves the trajectory and a figure)")
