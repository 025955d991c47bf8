"""``jaxsplit sweep``: one scheme over many cases, in resumable chunks.

The cases (``jaxsplit._sweep.sweep_cases``: a grid of initial states x inertia ratios x step
sizes, or random samples) are cut into chunks of ``--chunk-cases``; each chunk is evaluated
by ``jaxsplit._sweep.sweep`` and written to ``OUT/chunk-NNNNN.npz`` through a temporary file
and an atomic rename, so a chunk file is either complete or absent. ``OUT/manifest.json``
records every input; ``--resume`` checks the inputs are the same, skips the chunk files that
exist and computes the rest. The chunks are cut the same way in every run and each is
computed by the same code, so a resumed sweep equals an uninterrupted one bit for bit.
When all chunks exist they are merged into ``OUT/results.npz`` (cases, per-case results,
metadata) and ``OUT/summary.json``.
"""

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np

from ..core._errors import InputError
from . import _common as c

MANIFEST = "manifest.json"
RESULTS = "results.npz"
SUMMARY = "summary.json"
CASES = "cases.npz"
FORMAT_VERSION = 1
RUNS_DIR = "jaxsplit-runs"
# Host memory per case while merging: inputs and outputs (~30 numbers), twice.
BYTES_PER_CASE = 2 * 30 * 8

EXAMPLES = """\
examples:
  jaxsplit sweep --scheme strang --states 64 --ratios 1,0.5 0.8,0.6 --dt 0.1,0.05 --out sweep-strang
  jaxsplit sweep --scheme kahan-li-6 --split casimir --sampling random --samples 10000 \\
                 --seed 1 --t-end 20 --out big
  jaxsplit sweep ... --out big --resume        # after Ctrl-C or a kill: finish the rest

outputs (in --out DIR, default a new directory in ./jaxsplit-runs/): manifest.json (the
inputs), cases.npz, chunk-NNNNN.npz (one per finished chunk, written atomically),
results.npz (all cases and results, with metadata) and summary.json. Per case:
energy_error = max|H/H0 - 1| and casimir_error = max|C/C0 - 1| over every step, error =
max|m_n - m_ref(t_end)| against a high-order reference (reference_accuracy bounds its own
error), poisson_defect of one step at m0, the step size h actually used (t_end / n_steps)
and n_steps. An existing DIR is refused unless --resume (continue it; the inputs must be
the same) or --force (start it over).
"""


EXIT_HELP = ("exit status: 0 success; 2 bad input (one line on stderr, nothing run); 130 interrupted "
             "(Ctrl-C or SIGTERM: finished chunks are kept, --resume continues)")


def _ratio_pair(text):
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"an inertia ratio is a pair I2/I1,I3/I1, got {text!r}")
    values = tuple(c._number(p, "--ratios") for p in parts)
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"inertia ratios must be positive and finite, got {text!r}")
    return values


def _positive_list(name):
    def parse(text):
        parts = [p.strip() for p in str(text).split(",") if p.strip() != ""]
        if not parts:
            raise argparse.ArgumentTypeError(f"needs one or more comma-separated numbers, got {text!r}")
        values = tuple(c._number(p, name) for p in parts)
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise argparse.ArgumentTypeError(f"must be positive finite numbers, got {text!r}")
        return values

    return parse


def _range(name):
    def parse(text):
        values = _positive_list(name)(text)
        if len(values) != 2 or values[0] > values[1]:
            raise argparse.ArgumentTypeError(f"needs LOW,HIGH with 0 < LOW <= HIGH, got {text!r}")
        return values

    return parse


def _library_default(name):
    """A keyword default of ``jaxsplit._sweep.sweep``, so the CLI never drifts from the library."""
    import inspect

    from ..explore._sweep import sweep

    return inspect.signature(sweep).parameters[name].default


def add_parser(sub):
    ref_scheme, ref_angle = _library_default("reference_scheme"), _library_default("reference_angle")
    p = sub.add_parser(
        "sweep", help="evaluate a scheme over many cases, in resumable chunks",
        description="Evaluate one scheme over a grid (or random sample) of initial states, "
                    "inertia ratios and step sizes; results are written chunk by chunk so an "
                    "interrupted sweep resumes with --resume.",
        epilog=EXAMPLES + "\n" + EXIT_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("method")
    g.add_argument("--scheme", default="strang", help="any name from `jaxsplit schemes` (default strang)")
    g.add_argument("--split", choices=("axes", "casimir"), default="axes", help="(default axes)")
    g.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                   help="axis of the Casimir shift, with --split casimir (default auto)")
    g.add_argument("--t-end", type=c.positive_float, default=10.0, metavar="T",
                   help="integration time of every case (default 10)")
    g.add_argument("--reference-scheme", default=ref_scheme, metavar="NAME",
                   help=f"scheme of the reference solution, Casimir split (default {ref_scheme})")
    g.add_argument("--reference-angle", type=c.positive_float, default=ref_angle, metavar="RAD",
                   help=f"largest rotation per reference step, <= 0.5 (default {ref_angle:g})")
    g = p.add_argument_group("cases")
    g.add_argument("--sampling", choices=("grid", "random"), default="grid", help="(default grid)")
    g.add_argument("--states", type=c.positive_int, default=16, metavar="N",
                   help="grid: initial states on the unit sphere (Fibonacci lattice) (default 16)")
    g.add_argument("--ratios", type=_ratio_pair, nargs="+", default=[(1.0, 0.5)], metavar="R2,R3",
                   help="grid: inertia ratio pairs I2/I1,I3/I1 (default 1,0.5)")
    g.add_argument("--dt", type=_positive_list("--dt"), default=(0.1,), metavar="H[,H...]",
                   help="grid: step sizes (default 0.1)")
    g.add_argument("--samples", type=c.positive_int, metavar="N", help="random: number of cases")
    g.add_argument("--seed", type=int, default=0, help="random: seed (default 0)")
    g.add_argument("--ratio-range", type=_range("--ratio-range"), default=(0.3, 3.0), metavar="LO,HI",
                   help="random: range of I2/I1 and I3/I1, log-uniform (default 0.3,3)")
    g.add_argument("--dt-range", type=_range("--dt-range"), default=(0.01, 0.5), metavar="LO,HI",
                   help="random: range of step sizes, log-uniform (default 0.01,0.5)")
    g.add_argument("--allow-nonphysical", action="store_true",
                   help="keep bodies violating the triangle inequalities")
    g = p.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help="output directory (default: new one in ./jaxsplit-runs/)")
    g.add_argument("--chunk-cases", type=c.positive_int, default=256, metavar="N",
                   help="cases per chunk file (default 256)")
    g.add_argument("--resume", action="store_true", help="continue the sweep in --out DIR")
    g.add_argument("--max-memory", type=c.byte_size, metavar="SIZE",
                   help="refuse sweeps whose merged results need more (default: half the available memory)")
    c.add_common_flags(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- inputs


def _inputs(args) -> dict:
    """Every input that determines the results (compared on --resume)."""
    from ..core._schemes import schemes

    scheme = schemes[args.scheme].name
    reference = schemes[args.reference_scheme].name
    if args.reference_angle > 0.5:
        raise InputError(f"--reference-angle must be <= 0.5, got {args.reference_angle:g}")
    if args.shift_axis is not None and args.split != "casimir":
        raise InputError("--shift-axis applies only with --split casimir")
    s = schemes[scheme]
    if not s.pieces_allowed(3 if args.split == "axes" else 2):
        raise InputError(f"--scheme {scheme} is {s.form} (exactly two pieces) and does not fit "
                         "--split axes (three pieces); use --split casimir")
    inputs = {
        "scheme": scheme, "split": args.split,
        "shift_axis": None if args.split != "casimir" else (args.shift_axis or "auto"),
        "t_end": args.t_end, "reference_scheme": reference, "reference_angle": args.reference_angle,
        "sampling": args.sampling, "allow_nonphysical": args.allow_nonphysical,
        "chunk_cases": args.chunk_cases,
    }
    if args.sampling == "grid":
        if args.samples is not None:
            raise InputError("--samples applies only with --sampling random")
        inputs |= {"states": args.states, "ratios": [list(r) for r in args.ratios], "dt": list(args.dt)}
    else:
        if args.samples is None:
            raise InputError("--sampling random needs --samples N")
        inputs |= {"samples": args.samples, "seed": args.seed, "ratio_range": list(args.ratio_range),
                   "dt_range": list(args.dt_range)}
    return inputs


def _cases(inputs: dict) -> dict:
    from ..explore._sweep import physical, sweep_cases

    if inputs["sampling"] == "grid":
        ratios = np.asarray(inputs["ratios"], dtype=float)
        bad = ~physical(ratios)
        if bad.any() and not inputs["allow_nonphysical"]:
            r = ratios[bad][0]
            raise InputError(f"--ratios {r[0]:g},{r[1]:g} gives the body I = (1, {r[0]:g}, {r[1]:g}), which "
                             "violates the triangle inequalities; pass --allow-nonphysical to keep it")
        return sweep_cases(states=inputs["states"], ratios=ratios, step_sizes=inputs["dt"],
                           sampling="grid", dtype=np.float64)
    return sweep_cases(sampling="random", n_samples=inputs["samples"], seed=inputs["seed"],
                       ratio_range=inputs["ratio_range"], h_range=inputs["dt_range"],
                       physical_only=not inputs["allow_nonphysical"], dtype=np.float64)


def _chunk_path(out: Path, k: int) -> Path:
    return out / f"chunk-{k:05d}.npz"


def _prepare_dir(args, inputs, when) -> tuple[Path, bool]:
    """The output directory, ready to write; True when resuming an existing manifest."""
    if args.out is None:
        if args.resume:
            raise InputError("--resume needs --out DIR (the directory of the sweep to continue)")
        out = Path(RUNS_DIR) / f"sweep-{when}-{inputs['scheme']}"
        k = 2
        while out.exists():
            out = Path(RUNS_DIR) / f"sweep-{when}-{inputs['scheme']}-{k}"
            k += 1
    else:
        out = Path(args.out).expanduser()
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} exists and is not a directory")
    manifest = out / MANIFEST
    ours = [manifest, out / RESULTS, out / SUMMARY, out / CASES, *out.glob("chunk-*.npz")] if out.is_dir() else []
    existing = [p for p in ours if p.exists()]
    if args.resume and args.force:
        raise InputError("--resume and --force contradict each other (continue, or start over)")
    if existing and not (args.resume or args.force):
        raise InputError(f"--out {str(out)!r} already holds a sweep; pass --resume to continue it or "
                         "--force to start it over")
    if args.resume and manifest.exists():
        try:
            old = json.loads(manifest.read_text())
            old_inputs = old["inputs"]
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise InputError(f"cannot resume: {str(manifest)!r} is not a jaxsplit sweep manifest ({err})") from None
        new = json.loads(json.dumps(c.jsonable(inputs)))
        if old_inputs != new:
            diff = sorted(k for k in set(old_inputs) | set(new) if old_inputs.get(k) != new.get(k))
            shown = "; ".join(f"{k}: was {old_inputs.get(k)!r}, now {new.get(k)!r}" for k in diff)
            raise InputError(f"cannot resume {str(out)!r} with different inputs ({shown}); "
                             "use the original options, or --force to start over")
        return out, True
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"cannot create --out directory {str(out)!r}: {err.strerror or err}") from None
    c.check_output(out / MANIFEST, force=True, what="sweep manifest")  # writable?
    if args.force:
        for p in existing:
            p.unlink()
    return out, False


# --------------------------------------------------------------------------- run


class _Terminated(KeyboardInterrupt):
    pass


def run(args):
    from ..explore._sweep import sweep

    inputs = _inputs(args)
    cases = _cases(inputs)
    n = len(cases["h"])
    limit = args.max_memory or c.default_memory_limit()
    if n * BYTES_PER_CASE > limit:
        raise InputError(f"the sweep's {n:,} cases need about {c.format_bytes(n * BYTES_PER_CASE)} of memory to "
                         f"merge but the limit is {c.format_bytes(limit)} (--max-memory); split it into sweeps of "
                         f"at most {limit // BYTES_PER_CASE:,} cases (fewer --states/--ratios/--dt or --samples)")
    when = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out, resumed = _prepare_dir(args, inputs, when)
    for stale in out.glob(".*.tmp"):  # temporary files of a killed run
        stale.unlink(missing_ok=True)
    size = args.chunk_cases
    n_chunks = math.ceil(n / size)
    if not resumed:
        meta = c.run_metadata("sweep")
        manifest = {"format": FORMAT_VERSION, "inputs": inputs, "n_cases": n, "n_chunks": n_chunks,
                    "jaxsplit_version": meta["jaxsplit_version"], "jax_version": meta["jax_version"],
                    "created_utc": meta["created_utc"]}
        c.save_npz(out / CASES, cases)
        c.atomic_write(out / MANIFEST, lambda f: f.write(json.dumps(c.jsonable(manifest), indent=2).encode()))

    todo = [k for k in range(n_chunks) if not _chunk_ok(_chunk_path(out, k))]
    skipped = n_chunks - len(todo)
    if resumed and not args.quiet and not args.json:
        print(f"resuming {out}: {skipped} of {n_chunks} chunks already done", file=sys.stderr)
    progress = c.Progress(n, unit="cases", enabled=not args.quiet)
    start = time.perf_counter()
    done_cases = sum(min(size, n - k * size) for k in range(n_chunks) if k not in set(todo))
    previous = signal.getsignal(signal.SIGTERM)

    def on_term(signum, frame):
        raise _Terminated()

    signal.signal(signal.SIGTERM, on_term)
    computed = 0
    try:
        for k in todo:
            lo, hi = k * size, min(n, (k + 1) * size)
            piece = {key: np.asarray(v)[lo:hi] for key, v in cases.items()}
            shift = {"shift": _shift(inputs["shift_axis"])} if inputs["split"] == "casimir" else {}
            res = sweep(inputs["scheme"], piece, t_end=inputs["t_end"], split=inputs["split"], **shift,
                        reference_scheme=inputs["reference_scheme"],
                        reference_angle=inputs["reference_angle"], chunk_size=max(1, hi - lo))
            c.save_npz(_chunk_path(out, k), {"case_index": np.arange(lo, hi)} | {
                key: np.asarray(v) for key, v in res.items()})
            computed += 1
            done_cases += hi - lo
            progress.update(done_cases)
    except KeyboardInterrupt:
        progress.close()
        left = n_chunks - skipped - computed
        print(f"jaxsplit: interrupted: {n_chunks - left} of {n_chunks} chunks are saved in {out}; "
              f"continue with the same options and --out {out} --resume", file=sys.stderr)
        return c.EXIT_INTERRUPTED
    finally:
        signal.signal(signal.SIGTERM, previous)
    progress.close(done_cases)
    seconds = time.perf_counter() - start

    merged = _merge(out, cases, n_chunks, inputs)
    summary = _summary(merged, inputs, n, n_chunks, computed, skipped, seconds, out)
    c.atomic_write(out / SUMMARY, lambda f: f.write(json.dumps(c.jsonable(summary), indent=2).encode()))
    if args.json:
        c.print_json(summary)
    else:
        _print_summary(summary)
    return c.EXIT_OK


def _shift(value):
    """The library's 0-based shift from the CLI's 1-based --shift-axis label (or "auto")."""
    return "auto" if value in (None, "auto") else int(value) - 1


def _chunk_ok(path: Path) -> bool:
    if not path.exists():
        return False
    try:
        with np.load(path) as z:
            return "case_index" in z.files and len(z["case_index"]) > 0
    except Exception:  # noqa: BLE001 - truncated or foreign file (BadZipFile, OSError, ...): recompute
        return False


def _merge(out: Path, cases: dict, n_chunks: int, inputs: dict) -> dict:
    parts = []
    for k in range(n_chunks):
        with np.load(_chunk_path(out, k)) as z:
            parts.append({key: z[key] for key in z.files})
    merged = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    if not np.array_equal(merged["case_index"], np.arange(len(cases["h"]))):
        raise InputError(f"the chunk files in {str(out)!r} do not cover the cases; rerun with --force")
    results = {f"case_{k}": np.asarray(v) for k, v in cases.items()}
    results |= {k: v for k, v in merged.items() if k != "case_index"}
    meta = c.run_metadata("sweep") | {"inputs": inputs}
    c.save_npz(out / RESULTS, results | {"metadata": c.metadata_array(meta)})
    return results


def _stats(x):
    x = np.asarray(x, dtype=float)
    return {"max": float(np.max(x)), "median": float(np.median(x)), "min": float(np.min(x))}


def _summary(r, inputs, n, n_chunks, computed, skipped, seconds, out):
    return {
        "scheme": inputs["scheme"], "split": inputs["split"], "t_end": inputs["t_end"],
        "cases": n, "chunks": n_chunks, "chunks_computed": computed, "chunks_skipped": skipped,
        "energy_error": _stats(r["energy_error"]), "casimir_error": _stats(r["casimir_error"]),
        "error": _stats(r["error"]), "poisson_defect": _stats(r["poisson_defect"]),
        "reference_accuracy_max": float(np.max(r["reference_accuracy"])),
        "seconds": seconds, "out": str(out), "results": str(out / RESULTS),
    }


def _print_summary(s):
    print(f"jaxsplit sweep: {s['scheme']} ({s['split']} split), {s['cases']:,} cases to t = {s['t_end']:g} "
          f"in {s['chunks']} chunks ({s['chunks_computed']} computed, {s['chunks_skipped']} resumed) "
          f"in {s['seconds']:.1f} s")
    for key, label in (("energy_error", "max|H/H0 - 1|"), ("casimir_error", "max|C/C0 - 1|"),
                       ("error", "error vs reference"), ("poisson_defect", "Poisson defect")):
        st = s[key]
        print(f"  {label:<20} median {st['median']:.3e}   max {st['max']:.3e}")
    print(f"  reference accuracy   max {s['reference_accuracy_max']:.1e}")
    print(f"  wrote {s['results']} and {Path(s['out']) / SUMMARY}")
