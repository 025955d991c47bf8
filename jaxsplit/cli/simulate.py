"""``jaxsplit simulate``: integrate a free rigid body, save the trajectory and a figure.

With no arguments: the seed paper's symmetric body I = (2, 2, 1) from m0 = (0.6, 0, 0.8)
with Lie–Trotter, h = 0.01, 10 000 steps; the summary includes the error against the exact
solution (given for every symmetric body). Outputs go to a new, uniquely named pair
``jaxsplit-runs/simulate-<UTC time>-<scheme>.npz`` / ``.png`` (never overwriting
anything) unless ``--out`` names them or ``--no-save`` is given.
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
from ..systems._rigid_body import PAPER_BODY, PAPER_M0
from . import _args, _bounds, _chunked, _io, _metadata, _problem, _progress, _signals

EXIT_OK = 0
EXIT_NONFINITE = 3
DEFAULT_DT = 0.01
DEFAULT_STEPS = 10_000
RUNS_DIR = "jaxsplit-runs"
FORMATS = ("npz", "csv")
# Memory per saved state: t, step, m, energy, casimir, exact (10 numbers), twice (device + host).
BYTES_PER_SAVED = 2 * 10 * 8

EXAMPLES = """\
examples:
  jaxsplit simulate                                   # the paper's symmetric body, Lie-Trotter
  jaxsplit simulate --scheme strang --dt 0.05 --t-end 500 --out run.npz
  jaxsplit simulate --inertia 3,2,1.5 --m0 0.2,0.9,0.3 --scheme kahan-li-6 \\
                    --split casimir --steps 1e6 --save-every 100 --out asym.csv
  jaxsplit simulate --inertia 2,1,0.6667 --m0 0.4536,0,0.8912 --allow-nonphysical \\
                    --scheme strang --dt 0.1 --t-end 1000    # the GNI standard case
  jaxsplit simulate --json --no-save                  # one JSON object, no files
  jaxsplit simulate --dt -0.01 --steps 100            # backwards in time

outputs: --out PATH writes PATH (.npz, or .csv by suffix or --format) with metadata (every
input, versions, dtype) and a figure next to it (PATH with suffix .png; --figure moves it,
--no-figure drops it). Without --out the pair goes to a new file in ./jaxsplit-runs/ and
its name is printed; --no-save writes nothing. Existing files are never overwritten
without --force. Negative numbers may be given directly (--m0 -0.6,0,0.8).
"""


def add_parser(sub):
    p = sub.add_parser(
        "simulate", help="integrate a rigid body; save trajectory, figure, summary",
        description="Integrate the free rigid body with a splitting scheme and report the "
                    "energy and Casimir errors (and the error against the exact solution when "
                    "the body is symmetric).",
        epilog=EXAMPLES + "\n" + _args.EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("problem")
    g.add_argument("--inertia", type=_args.vector3("--inertia", "I1,I2,I3"), default=PAPER_BODY, metavar="I1,I2,I3",
                   help=f"principal moments of inertia, all > 0 (default {_problem.fmt_vec(PAPER_BODY)})")
    g.add_argument("--m0", type=_args.vector3("--m0"), default=PAPER_M0, metavar="A,B,C",
                   help=f"initial body angular momentum (default {_problem.fmt_vec(PAPER_M0)})")
    g.add_argument("--allow-nonphysical", action="store_true",
                   help="integrate a body that violates the triangle inequalities I1 + I2 >= I3 (etc.)")
    g = p.add_argument_group("method")
    g.add_argument("--scheme", default="lie-trotter",
                   help="any name from `jaxsplit schemes` (default lie-trotter)")
    g.add_argument("--split", choices=("axes", "casimir"), default="axes",
                   help="axes: three rotations (the paper); casimir: two, shifted by C/I_k (default axes)")
    g.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                   help="axis k of the Casimir shift, with --split casimir (default auto)")
    g.add_argument("--dt", type=_args.nonzero_float, default=DEFAULT_DT, metavar="H",
                   help=f"step size, non-zero; negative runs backwards (default {DEFAULT_DT})")
    n = g.add_mutually_exclusive_group()
    n.add_argument("--steps", type=_args.positive_int, metavar="N",
                   help=f"number of steps (default {DEFAULT_STEPS:,})")
    n.add_argument("--t-end", type=_args.positive_float, metavar="T",
                   help="duration; steps = round(T / |H|)")
    g = p.add_argument_group("output")
    g.add_argument("--save-every", type=_args.positive_int, default=1, metavar="K",
                   help="keep every K-th state (and the last one); the reported errors are maxima over "
                        "the kept states (default 1)")
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


def _steps(args) -> int:
    """The step count, bounded (``--steps``, or ``--t-end`` / ``--dt`` without overflow)."""
    if args.t_end is None:
        n = args.steps or DEFAULT_STEPS
        return _bounds.at_most(n, _bounds.MAX_STEPS, "--steps", "step indices exact in float64")
    notes = []
    n = _bounds.step_count(args.t_end, args.dt, notes=notes)
    for note in notes:
        print(f"jaxsplit: note: {note}", file=sys.stderr)
    return n


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
        print(f"jaxsplit: note: cannot write to ./{RUNS_DIR} ({reason}); no files written "
              "(give --out PATH)", file=sys.stderr)
        return None, None, None


# --------------------------------------------------------------------------- run


def run(args):
    with _io.Outputs(force=args.force) as outputs:
        return _run(args, outputs)


class _Plan(NamedTuple):
    """Everything decided before the run: validated, bounded and claimed."""

    body: object
    m0: np.ndarray
    scheme: object
    shift: object
    axis: int | None
    n_steps: int
    save_every: int
    out: Path | None
    fmt: str | None
    figure: Path | None


def _plan(args, outputs) -> _Plan:
    body = _problem.body(args.inertia, args.allow_nonphysical)
    m0 = _problem.initial_state(args.m0, args.inertia)
    scheme, shift = _problem.scheme_and_shift(args, body)
    n_steps = _steps(args)
    save_every = _bounds.at_most(args.save_every, _bounds.MAX_STEPS, "--save-every", "step indices exact in float64")
    _bounds.saved_states(n_steps, save_every, BYTES_PER_SAVED, _bounds.memory_limit(args.max_memory))
    when = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out, fmt, figure = _output_paths(args, outputs, when)
    try:
        axis = body.symmetry_axis()
    except InputError:
        axis = None
    return _Plan(body, m0, scheme, shift, axis, n_steps, save_every, out, fmt, figure)


def _run(args, outputs):
    import jax.numpy as jnp

    from ..systems._splitting import splitting

    plan = _plan(args, outputs)  # everything checked before any work
    stop = _signals.current()
    step = splitting(plan.body, plan.scheme, args.split, **_problem.split_options(args.split, plan.shift))
    progress = _progress.Progress(plan.n_steps, enabled=not args.quiet)
    with stop.defer():  # a signal stops the run after the current chunk
        result = _chunked.run_chunked(step, jnp.asarray(plan.m0), args.dt, plan.n_steps, plan.save_every,
                                      flows_per_step=getattr(step, "flows_per_step", 1), progress=progress,
                                      stop=lambda: stop.requested)
    with stop.critical():  # from here on a signal only changes the exit status: the outputs complete
        return _report(args, outputs, plan, result)


def _report(args, outputs, plan, result):
    """Diagnostics, files and summary of a finished or stopped run (never lose work)."""
    import jax.numpy as jnp

    from ..systems._rigid_body import symmetric_solution

    body, m0, scheme, shift, axis, n_steps, save_every, out, fmt, figure = plan
    seconds = result.seconds
    # ---- diagnostics
    m = result.x
    t = result.steps * args.dt
    inverse = 1 / np.asarray(args.inertia)

    def relative(values):
        return values / values[0] - 1 if values[0] != 0 else values - values[0]

    with np.errstate(over="ignore", invalid="ignore"):  # a blown-up run may overflow here
        energy = 0.5 * np.sum(m * m * inverse, axis=1)
        casimir = 0.5 * np.sum(m * m, axis=1)
        energy_error, casimir_error = relative(energy), relative(casimir)
    exact = exact_error = None
    if axis is not None:
        exact = np.asarray(symmetric_solution(body, jnp.asarray(m0), jnp.asarray(t), axis=axis))
        exact_error = np.max(np.abs(m - exact), axis=1)
    status = "ok" if result.nonfinite_step is None and not result.interrupted else (
        "nonfinite" if result.nonfinite_step is not None else "interrupted")
    summary = {
        "scheme": scheme.name, "order": scheme.order, "split": args.split,
        "shift_axis": None if args.split != "casimir" else shift,
        "inertia": list(args.inertia), "m0": m0.tolist(), "dt": args.dt,
        "steps": result.completed, "steps_requested": n_steps, "t_end": result.completed * args.dt,
        "save_every": save_every, "saved_states": len(m),
        "energy_error_max": float(np.max(np.abs(energy_error))),
        "casimir_error_max": float(np.max(np.abs(casimir_error))),
        "exact_error_max": None if exact_error is None else float(np.max(exact_error)),
        "symmetric_axis": None if axis is None else axis + 1,
        "seconds": seconds, "steps_per_second": result.completed / seconds if seconds > 0 else None,
        "status": status, "nonfinite_step": result.nonfinite_step,
        "dtype": "float64",
    }

    # ---- outputs (also, and especially, for a stopped run: never lose work)
    meta = _metadata.run_metadata("simulate") | {
        k: summary[k] for k in ("scheme", "order", "split", "shift_axis", "inertia", "m0", "dt",
                                "steps_requested", "save_every", "status", "nonfinite_step")
    } | {"steps_completed": result.completed, "allow_nonphysical": args.allow_nonphysical}
    written = {}
    if out is not None:
        arrays = {"t": t, "step": result.steps, "m": m, "energy": energy, "casimir": casimir}
        if exact is not None:
            arrays["m_exact"] = exact
        _write_trajectory(outputs, out, fmt, arrays, meta)
        written["trajectory"] = str(out)
    if figure is not None:
        from . import _figures as _plots

        title = (f"{scheme.name} ({args.split} split), I = ({_problem.fmt_vec(args.inertia)}), "
                 f"m0 = ({_problem.fmt_vec(m0)}), h = {args.dt:g}, {result.completed:,} steps"
                 + ("" if status == "ok" else f" [{status}]"))
        fig = _plots.simulate_figure(t, m, energy_error, casimir_error, args.inertia, title=title,
                                     exact_error=exact_error)
        outputs.write(figure, lambda f: _plots.save_figure(fig, f))
        written["figure"] = str(figure)
    summary["outputs"] = written

    if args.json:
        _metadata.print_json(summary)
    else:
        _print_summary(summary, axis)
    if result.nonfinite_step is not None:
        k = result.nonfinite_step
        print(f"jaxsplit: error: the state became non-finite at step {k:,} (t = {k * args.dt:g}); "
              f"kept the {result.completed:,} steps before it" + (" (written)" if written else ""),
              file=sys.stderr)
        return EXIT_NONFINITE
    if result.interrupted:
        print(f"jaxsplit: interrupted ({_signals.current().signal_name}) after {result.completed:,} of {n_steps:,} "
              "steps; kept what was computed"
              + (" (written)" if written else ""), file=sys.stderr)
        return _signals.EXIT_INTERRUPTED
    return EXIT_OK


def _write_trajectory(outputs, path, fmt, arrays, meta):
    if fmt == "npz":
        outputs.write_npz(path, arrays | {"metadata": _metadata.metadata_array(meta)})
        return
    import json

    columns = [("step", arrays["step"]), ("t", arrays["t"])]
    columns += [(f"m{i + 1}", arrays["m"][:, i]) for i in range(3)]
    columns += [("energy", arrays["energy"]), ("casimir", arrays["casimir"])]
    if "m_exact" in arrays:
        columns += [(f"m{i + 1}_exact", arrays["m_exact"][:, i]) for i in range(3)]
    header = "metadata: " + json.dumps(_metadata.jsonable(meta)) + "\n" + ",".join(name for name, _ in columns)
    data = np.column_stack([np.asarray(v, dtype=np.float64) for _, v in columns])
    fmts = ["%d"] + ["%.17g"] * (len(columns) - 1)
    outputs.write(path, lambda f: np.savetxt(f, data, delimiter=",", header=header, fmt=fmts, comments="# "))


def _print_summary(s, axis):
    body = f"I = ({_problem.fmt_vec(s['inertia'])})" + (f", symmetric about axis {axis + 1}" if axis is not None else "")
    split = s["split"] + (f" (shift axis {s['shift_axis']})" if s["split"] == "casimir" else "")
    print(f"jaxsplit simulate: {s['scheme']} (order {s['order']}), {split} split, h = {s['dt']:g}, "
          f"{s['steps']:,} steps to t = {s['t_end']:g}")
    print(f"  body {body}; m0 = ({_problem.fmt_vec(s['m0'])})")
    every = "" if s["save_every"] == 1 else f", every {s['save_every']:,}th step"
    print(f"  over the {s['saved_states']:,} saved states{every}:")
    print(f"  max relative energy error    {s['energy_error_max']:.3e}   max|H/H0 - 1|")
    print(f"  max relative Casimir error   {s['casimir_error_max']:.3e}   max|C/C0 - 1|")
    if s["exact_error_max"] is not None:
        print(f"  max error vs exact solution  {s['exact_error_max']:.3e}   max|m - m_exact| (symmetric body)")
    rate = s["steps_per_second"]
    print(f"  {s['steps']:,} steps in {s['seconds']:.2f} s" + (f" ({rate:,.0f} steps/s, compilation included)"
                                                              if rate and math.isfinite(rate) else ""))
    outs = s["outputs"]
    if outs:
        print("  wrote " + ", ".join(f"{k} {v}" for k, v in outs.items()))
    else:
        print("  no files written (--out PATH saves the trajectory and a figure)")
