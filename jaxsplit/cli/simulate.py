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

import numpy as np

from ..core._errors import InputError
from ..systems._rigid_body import PAPER_BODY, PAPER_M0
from . import _common as c

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
        epilog=EXAMPLES + "\n" + c.EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("problem")
    g.add_argument("--inertia", type=c.vector3("--inertia", "I1,I2,I3"), default=PAPER_BODY, metavar="I1,I2,I3",
                   help=f"principal moments of inertia, all > 0 (default {c.fmt_vec(PAPER_BODY)})")
    g.add_argument("--m0", type=c.vector3("--m0"), default=PAPER_M0, metavar="A,B,C",
                   help=f"initial body angular momentum (default {c.fmt_vec(PAPER_M0)})")
    g.add_argument("--allow-nonphysical", action="store_true",
                   help="integrate a body that violates the triangle inequalities I1 + I2 >= I3 (etc.)")
    g = p.add_argument_group("method")
    g.add_argument("--scheme", default="lie-trotter",
                   help="any name from `jaxsplit schemes` (default lie-trotter)")
    g.add_argument("--split", choices=("axes", "casimir"), default="axes",
                   help="axes: three rotations (the paper); casimir: two, shifted by C/I_k (default axes)")
    g.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                   help="axis k of the Casimir shift, with --split casimir (default auto)")
    g.add_argument("--dt", type=c.nonzero_float, default=DEFAULT_DT, metavar="H",
                   help=f"step size, non-zero; negative runs backwards (default {DEFAULT_DT})")
    n = g.add_mutually_exclusive_group()
    n.add_argument("--steps", type=c.positive_int, metavar="N",
                   help=f"number of steps (default {DEFAULT_STEPS:,})")
    n.add_argument("--t-end", type=c.positive_float, metavar="T",
                   help="duration; steps = round(T / |H|)")
    g = p.add_argument_group("output")
    g.add_argument("--save-every", type=c.positive_int, default=1, metavar="K",
                   help="keep every K-th state (and the last one); the reported errors are maxima over "
                        "the kept states (default 1)")
    g.add_argument("--out", metavar="PATH", help="trajectory file (.npz or .csv)")
    g.add_argument("--format", choices=FORMATS, help="trajectory format (default: from the suffix of --out, else npz)")
    g.add_argument("--figure", metavar="PNG", help="figure path (default: --out with suffix .png)")
    g.add_argument("--no-figure", action="store_true", help="do not draw the figure")
    g.add_argument("--no-save", action="store_true", help="write no files; print the summary only")
    g.add_argument("--max-memory", type=c.byte_size, metavar="SIZE",
                   help="refuse runs whose saved states need more (default: half the available memory)")
    c.add_common_flags(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- planning


def _steps(args) -> int:
    if args.t_end is None:
        return args.steps or DEFAULT_STEPS
    n = round(args.t_end / abs(args.dt))
    if n < 1:
        raise InputError(f"--t-end {args.t_end:g} is shorter than one step of --dt {args.dt:g}")
    if abs(n * abs(args.dt) - args.t_end) > 1e-9 * args.t_end:
        print(f"jaxsplit: note: --t-end {args.t_end:g} is not a whole number of steps of --dt {args.dt:g}; "
              f"integrating {n:,} steps to t = {n * args.dt:g}", file=sys.stderr)
    return n


def _output_paths(args, when: str):
    """(trajectory path, format, figure path or None); all checked before running."""
    if args.no_save:
        if args.out or args.figure:
            raise InputError("--no-save contradicts --out/--figure")
        return None, None, None
    if args.out is None:
        if args.figure:
            return None, None, c.check_output(args.figure, args.force, "figure")
        return _default_outputs(args, when)
    out = Path(args.out).expanduser()
    if args.out.endswith(("/", os.sep)) or out.is_dir():
        raise InputError(f"--out {args.out!r} is a directory; give a file name such as {str(out / 'run.npz')!r}")
    suffix = out.suffix.lower().lstrip(".")
    if suffix in FORMATS:
        fmt = suffix
        if args.format and args.format != fmt:
            raise InputError(f"--format {args.format} conflicts with the suffix of --out {str(out)!r}")
    elif suffix == "" or out.name.endswith("."):
        fmt = args.format or "npz"
        out = out.with_name(out.name.rstrip(".") + "." + fmt)
    elif args.format:
        fmt = args.format
    else:
        raise InputError(f"--out {str(out)!r}: suffix must be .npz or .csv (or give --format npz|csv)")
    out = c.check_output(out, args.force, "trajectory")
    figure = None
    if not args.no_figure:
        figure = Path(args.figure).expanduser() if args.figure else out.with_suffix(".png")
        if figure == out:
            raise InputError(f"--figure {str(figure)!r} is the trajectory file itself")
        figure = c.check_output(figure, args.force, "figure")
    return out, fmt, figure


def _default_outputs(args, when: str):
    """A fresh name in ./jaxsplit-runs/ (created); None when the directory is not writable."""
    fmt = args.format or "npz"
    base = Path(RUNS_DIR)
    try:
        base.mkdir(exist_ok=True)
        stem = f"simulate-{when}-{args.scheme}"
        for k in range(1, 10_000):
            name = stem if k == 1 else f"{stem}-{k}"
            out = base / f"{name}.{fmt}"
            figure = None if args.no_figure else out.with_suffix(".png")
            if not out.exists() and (figure is None or not figure.exists()):
                break
        out = c.check_output(out, False, "trajectory")
    except (OSError, InputError) as err:
        reason = err.strerror if isinstance(err, OSError) else str(err)
        print(f"jaxsplit: note: cannot write to ./{RUNS_DIR} ({reason}); no files written "
              "(give --out PATH)", file=sys.stderr)
        return None, None, None
    return out, fmt, figure


# --------------------------------------------------------------------------- run


def run(args):
    import jax.numpy as jnp

    from ..systems._rigid_body import symmetric_solution
    from ..systems._splitting import splitting

    # ---- validate everything before any work
    body = c.check_body(args.inertia, args.allow_nonphysical)
    m0 = np.asarray(args.m0, dtype=np.float64)
    with np.errstate(over="ignore"):
        if not (np.isfinite(0.5 * np.sum(m0 * m0)) and np.isfinite(0.5 * np.sum(m0 * m0 / np.asarray(args.inertia)))):
            raise InputError(f"--m0 {c.fmt_vec(m0)} is too large: its energy or |m0|^2 overflows float64")
    scheme, shift = c.resolve_scheme_and_shift(args, body)
    n_steps = _steps(args)
    save_every = args.save_every
    n_saved = n_steps // save_every + 2
    limit = args.max_memory or c.default_memory_limit()
    c.check_memory(n_saved, BYTES_PER_SAVED, limit, steps=n_steps, save_every=save_every)
    when = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out, fmt, figure = _output_paths(args, when)
    try:
        axis = body.symmetry_axis()
    except InputError:
        axis = None

    # ---- run
    kwargs = c.split_options(args.split, shift)
    step = splitting(body, scheme, args.split, **kwargs)
    progress = c.Progress(n_steps, enabled=not args.quiet)
    result = c.run_chunked(step, jnp.asarray(m0), args.dt, n_steps, save_every,
                           flows_per_step=getattr(step, "flows_per_step", 1), progress=progress)
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
    meta = c.run_metadata("simulate") | {
        k: summary[k] for k in ("scheme", "order", "split", "shift_axis", "inertia", "m0", "dt",
                                "steps_requested", "save_every", "status", "nonfinite_step")
    } | {"steps_completed": result.completed, "allow_nonphysical": args.allow_nonphysical}
    written = {}
    if out is not None:
        arrays = {"t": t, "step": result.steps, "m": m, "energy": energy, "casimir": casimir}
        if exact is not None:
            arrays["m_exact"] = exact
        _write_trajectory(out, fmt, arrays, meta)
        written["trajectory"] = str(out)
    if figure is not None:
        from . import _figures as _plots

        title = (f"{scheme.name} ({args.split} split), I = ({c.fmt_vec(args.inertia)}), "
                 f"m0 = ({c.fmt_vec(m0)}), h = {args.dt:g}, {result.completed:,} steps"
                 + ("" if status == "ok" else f" [{status}]"))
        fig = _plots.simulate_figure(t, m, energy_error, casimir_error, args.inertia, title=title,
                                     exact_error=exact_error)
        c.atomic_write(figure, lambda f: _plots.save_figure(fig, f))
        written["figure"] = str(figure)
    summary["outputs"] = written

    if args.json:
        c.print_json(summary)
    else:
        _print_summary(summary, axis)
    if result.nonfinite_step is not None:
        k = result.nonfinite_step
        print(f"jaxsplit: error: the state became non-finite at step {k:,} (t = {k * args.dt:g}); "
              f"kept the {result.completed:,} steps before it" + (" (written)" if written else ""),
              file=sys.stderr)
        return c.EXIT_NONFINITE
    if result.interrupted:
        print(f"jaxsplit: interrupted after {result.completed:,} of {n_steps:,} steps; kept what was computed"
              + (" (written)" if written else ""), file=sys.stderr)
        return c.EXIT_INTERRUPTED
    return c.EXIT_OK


def _write_trajectory(path, fmt, arrays, meta):
    if fmt == "npz":
        c.save_npz(path, arrays | {"metadata": c.metadata_array(meta)})
        return
    import json

    columns = [("step", arrays["step"]), ("t", arrays["t"])]
    columns += [(f"m{i + 1}", arrays["m"][:, i]) for i in range(3)]
    columns += [("energy", arrays["energy"]), ("casimir", arrays["casimir"])]
    if "m_exact" in arrays:
        columns += [(f"m{i + 1}_exact", arrays["m_exact"][:, i]) for i in range(3)]
    header = "metadata: " + json.dumps(c.jsonable(meta)) + "\n" + ",".join(name for name, _ in columns)
    data = np.column_stack([np.asarray(v, dtype=np.float64) for _, v in columns])
    fmts = ["%d"] + ["%.17g"] * (len(columns) - 1)
    c.atomic_write(path, lambda f: np.savetxt(f, data, delimiter=",", header=header, fmt=fmts, comments="# "))


def _print_summary(s, axis):
    body = f"I = ({c.fmt_vec(s['inertia'])})" + (f", symmetric about axis {axis + 1}" if axis is not None else "")
    split = s["split"] + (f" (shift axis {s['shift_axis']})" if s["split"] == "casimir" else "")
    print(f"jaxsplit simulate: {s['scheme']} (order {s['order']}), {split} split, h = {s['dt']:g}, "
          f"{s['steps']:,} steps to t = {s['t_end']:g}")
    print(f"  body {body}; m0 = ({c.fmt_vec(s['m0'])})")
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
