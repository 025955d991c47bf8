"""``jaxsplit sweep``: one scheme over many cases, in resumable chunks.

The cases (``explore.sweep_cases``: a grid of initial states x inertia ratios x step
sizes, or random samples) are cut into chunks of ``--chunk-cases``; each chunk is evaluated
by ``explore.sweep`` and written to ``OUT/chunk-NNNNN.npz`` by the one writer (atomic, in
the locked output directory), so a chunk file is either complete or absent and two sweeps
never share a directory. ``OUT/manifest.json`` records every input.

Every chunk file carries its *proof*: the digest of the inputs it was computed under, its
case range, and a SHA-256 over those, its cases and its results. ``--resume`` reuses a
chunk only when the proof holds for the current inputs and cases; a chunk of other inputs
is refused (exit 2: it is another sweep's work), a truncated, edited or unprovable one is
recomputed. The chunks are cut the same way in every run and each is computed by the same
code, so a resumed sweep equals an uninterrupted one bit for bit. When all chunks exist
they are merged into ``OUT/results.npz`` (cases, per-case results, metadata) and
``OUT/summary.json``.

Every size is bounded before the directory is touched: the number of cases (memory), each
case's step count (the library's int32 counter) and the reference's step count.
"""

import argparse
import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ..core._errors import InputError
from . import _args, _bounds, _io, _metadata, _progress, _signals

MANIFEST = "manifest.json"
RESULTS = "results.npz"
SUMMARY = "summary.json"
CASES = "cases.npz"
FIGURE = "sweep.png"
RANDOM_BINS = 4  # random sampling: each parameter's range cut into this many log-spaced bins
FORMAT_VERSION = 2  # 2: chunks carry a proof of their inputs, cases and results
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
results.npz (all cases and results, with metadata), summary.json (with the tables grouped
by inertia ratios and by step size that the summary prints) and sweep.png (the errors
against h, one line per inertia ratio pair: median and max over the states). Per case:
energy_error = max|H/H0 - 1| and casimir_error = max|C/C0 - 1| over every step, error =
max|m_n - m_ref(t_end)| against a high-order reference (reference_accuracy bounds its own
error), poisson_defect of one step at m0, the step size h actually used (t_end / n_steps)
and n_steps. A DIR that holds files (a sweep's or anyone's) is refused unless --resume
(continue the sweep in it; the inputs must be the same) or --force (start the sweep over;
files that are not the sweep's are left alone); --resume needs a sweep to continue.
"""


EXIT_HELP = ("exit status: 0 success; 2 bad input (one line on stderr, nothing run; also: --out is in use by "
             "another run, or holds chunks of other inputs); 130 interrupted (SIGINT or SIGTERM: finished chunks "
             "are kept, --resume continues)")


def _ratio_pair(text):
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"an inertia ratio is a pair I2/I1,I3/I1, got {text!r}")
    values = tuple(_args.number(p, "--ratios") for p in parts)
    if not all(math.isfinite(v) and v > 0 and math.isfinite(1 / v) for v in values):
        raise argparse.ArgumentTypeError(f"inertia ratios must be positive and finite (with finite inverses), "
                                         f"got {text!r}")
    return values


def _range(name):
    def parse(text):
        values = _args.positive_list(name)(text)
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
    g.add_argument("--system", choices=("rigid-body", "attitude", "heavy-top", "gravity-gradient"),
                   default="rigid-body", help="rigid-body only (default): the cases are free bodies (initial "
                                              "states x inertia ratios x step sizes); other systems are refused "
                                              "with the library call that sweeps them")
    g.add_argument("--scheme", default="strang", help="any name from `jaxsplit schemes` (default strang)")
    g.add_argument("--split", choices=("axes", "casimir"), default=None,
                   help="(default axes, or casimir for a scheme of exactly two pieces)")
    g.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                   help="axis of the Casimir shift, with --split casimir (default auto)")
    g.add_argument("--t-end", type=_args.positive_float, default=10.0, metavar="T",
                   help="integration time of every case (default 10)")
    g.add_argument("--reference-scheme", default=ref_scheme, metavar="NAME",
                   help=f"scheme of the reference solution, Casimir split (default {ref_scheme})")
    g.add_argument("--reference-angle", type=_args.positive_float, default=ref_angle, metavar="RAD",
                   help=f"largest rotation per reference step, <= 0.5 (default {ref_angle:g})")
    g = p.add_argument_group("cases")
    g.add_argument("--sampling", choices=("grid", "random"), default="grid", help="(default grid)")
    g.add_argument("--states", type=_args.positive_int, default=16, metavar="N",
                   help="grid: initial states on the unit sphere (Fibonacci lattice) (default 16)")
    g.add_argument("--ratios", type=_ratio_pair, nargs="+", default=[(1.0, 0.5)], metavar="R2,R3",
                   help="grid: inertia ratio pairs I2/I1,I3/I1 (default 1,0.5)")
    g.add_argument("--dt", type=_args.positive_list("--dt"), default=(0.1,), metavar="H[,H...]",
                   help="grid: step sizes (default 0.1)")
    g.add_argument("--samples", type=_args.positive_int, metavar="N", help="random: number of cases")
    g.add_argument("--seed", type=_args.seed, default=0, help="random: seed (default 0)")
    g.add_argument("--ratio-range", type=_range("--ratio-range"), default=(0.3, 3.0), metavar="LO,HI",
                   help="random: range of I2/I1 and I3/I1, log-uniform (default 0.3,3)")
    g.add_argument("--dt-range", type=_range("--dt-range"), default=(0.01, 0.5), metavar="LO,HI",
                   help="random: range of step sizes, log-uniform (default 0.01,0.5)")
    g.add_argument("--allow-nonphysical", action="store_true",
                   help="keep bodies violating the triangle inequalities")
    g = p.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help="output directory (default: new one in ./jaxsplit-runs/)")
    g.add_argument("--chunk-cases", type=_args.positive_int, default=256, metavar="N",
                   help="cases per chunk file (default 256)")
    g.add_argument("--resume", action="store_true", help="continue the sweep in --out DIR")
    g.add_argument("--max-memory", type=_args.byte_size, metavar="SIZE",
                   help="refuse sweeps whose merged results need more (default: half the available memory)")
    g.add_argument("--no-figure", action="store_true", help=f"do not draw {FIGURE}")
    _args.add_common_flags(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- inputs


def _inputs(args) -> dict:
    """Every input that determines the results (compared on --resume)."""
    if args.system != "rigid-body":
        raise InputError(f"--system {args.system}: the command-line sweep runs free-body cases (initial states x "
                         "inertia ratios x step sizes); sweep other systems with the library, jaxsplit.sweep(scheme, "
                         "cases, t_end=..., system=<a family params -> system>) (see its docstring)")
    s = _bounds.scheme(args.scheme)
    scheme = s.name
    if args.split is None:  # a scheme of exactly two pieces, or a --shift-axis, asks for the Casimir split
        args.split = "axes" if s.pieces_allowed(3) and args.shift_axis is None else "casimir"
    reference = _bounds.scheme(args.reference_scheme, "--reference-scheme").name
    if args.reference_angle > 0.5:
        raise InputError(f"--reference-angle must be <= 0.5, got {args.reference_angle:g}")
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
    grid, random = args.sampling == "grid", args.sampling == "random"
    _args.refuse_unused(args, {"shift_axis": (args.split == "casimir", "with --split casimir"),
                               "states": (grid, "with --sampling grid"), "ratios": (grid, "with --sampling grid"),
                               "dt": (grid, "with --sampling grid"), "samples": (random, "with --sampling random"),
                               "seed": (random, "with --sampling random"),
                               "ratio_range": (random, "with --sampling random (and --samples N)"),
                               "dt_range": (random, "with --sampling random (and --samples N)")})
    if args.sampling == "grid":
        inputs |= {"states": args.states, "ratios": [list(r) for r in args.ratios], "dt": list(args.dt)}
    else:
        if args.samples is None:
            raise InputError("--sampling random needs --samples N")
        inputs |= {"samples": args.samples, "seed": args.seed, "ratio_range": list(args.ratio_range),
                   "dt_range": list(args.dt_range)}
    return inputs


def _case_count(inputs: dict) -> int:
    """The number of cases, known before any is built."""
    if inputs["sampling"] == "grid":
        return inputs["states"] * len(inputs["ratios"]) * len(inputs["dt"])
    return inputs["samples"]


def _cases(inputs: dict) -> dict:
    from ..explore._sweep import sweep_cases
    from ..systems._rigid_body import check_moments

    if inputs["sampling"] == "grid":
        ratios = np.asarray(inputs["ratios"], dtype=float)
        for r in ratios:  # the library's check of a body, naming the option
            check_moments(np.array([1.0, *r]), f"--ratios {r[0]:g},{r[1]:g} gives the body I =",
                          inputs["allow_nonphysical"], "--allow-nonphysical")
        return sweep_cases(states=inputs["states"], ratios=ratios, step_sizes=inputs["dt"], physical_only=False,
                           sampling="grid", dtype=np.float64)
    return sweep_cases(sampling="random", n_samples=inputs["samples"], seed=inputs["seed"],
                       ratio_range=inputs["ratio_range"], h_range=inputs["dt_range"],
                       physical_only=not inputs["allow_nonphysical"], dtype=np.float64)


def _bounded_cases(inputs: dict, limit: int) -> dict:
    """The cases, after bounding their number (memory), each one's step count (the library
    counts them in int32) and the reference's step count; nothing is built before the first."""
    import jax.numpy as jnp

    from ..explore._sweep import MAX_STEPS, reference_steps
    from ..systems._rigid_body import RigidBody

    n = _case_count(inputs)
    _bounds.memory(n * BYTES_PER_CASE, limit, f"merging the sweep's {n:,} cases",
                   f"split it into sweeps of at most {max(1, limit // BYTES_PER_CASE):,} cases "
                   "(fewer --states/--ratios/--dt or --samples)")
    cases = _cases(inputs)
    dt_option = "--dt" if inputs["sampling"] == "grid" else "--dt-range (low end)"
    _bounds.step_count(inputs["t_end"], float(np.min(cases["h"])), limit=MAX_STEPS, options=("--t-end", dt_option),
                       why="a sweep counts the steps of each case in int32", at_least_one=False)
    rates = RigidBody(jnp.asarray(cases["inertia"]), allow_nonphysical=True).max_rate(jnp.asarray(cases["m0"]))
    reference_steps(np.asarray(rates), inputs["t_end"], inputs["reference_angle"])  # InputError beyond int32
    return cases


def _chunk_path(out: Path, k: int) -> Path:
    return out / f"chunk-{k:05d}.npz"


def _sweep_files(out: Path) -> list[Path]:
    names = [MANIFEST, RESULTS, SUMMARY, CASES, FIGURE]
    return [p for p in [*(out / name for name in names), *sorted(out.glob("chunk-*.npz"))] if p.exists()]


def _prepare_dir(args, outputs, inputs, when) -> tuple[Path, bool]:
    """The claimed (locked) output directory; True when resuming an existing manifest."""
    if args.resume and args.force:
        raise InputError("--resume and --force contradict each other (continue, or start over)")
    if args.out is None:
        if args.resume:
            raise InputError("--resume needs --out DIR (the directory of the sweep to continue)")
        out = _fresh_directory(outputs, f"sweep-{when}-{inputs['scheme']}")
    else:
        out = outputs.directory(args.out, "--out directory", resume=args.resume)  # locked: a second sweep into it exits 2 here
    shown = args.out if args.out is not None else str(out)
    existing = _sweep_files(out)
    if args.resume and not existing:
        raise InputError(f"nothing to resume: --out {shown!r} holds no sweep; run without --resume to start one")
    if existing and not (args.resume or args.force):
        raise InputError(f"--out {shown!r} already holds a sweep; pass --resume to continue it or "
                         "--force to start it over")
    theirs = sorted(p.name for p in out.iterdir() if p not in existing and not p.name.startswith(_io.TEMP_PREFIX)
                    and p.name != _io.DIRECTORY_LOCK)
    if theirs and not (args.resume or args.force):  # a directory of someone else's files: not ours to fill
        raise InputError(f"--out {shown!r} is not empty (it holds {theirs[0]!r}{' and more' if len(theirs) > 1 else ''});"
                         " give a new or empty directory, or --force to write the sweep beside those files")
    outputs.remove_temporaries(out)  # of a killed run (we hold the lock)
    manifest = out / MANIFEST
    if args.resume and manifest.exists():
        old_inputs = _manifest_inputs(manifest)
        new = json.loads(json.dumps(_metadata.jsonable(inputs)))
        if old_inputs != new:
            diff = sorted(k for k in set(old_inputs) | set(new) if old_inputs.get(k) != new.get(k))
            shown_diff = "; ".join(f"{k}: was {old_inputs.get(k)!r}, now {new.get(k)!r}" for k in diff)
            raise InputError(f"cannot resume {shown!r} with different inputs ({shown_diff}); "
                             "use the original options, or --force to start over")
        return out, True
    if args.force:
        with _signals.current().critical():
            for p in existing:
                p.unlink()
    return out, False


def _fresh_directory(outputs, stem: str) -> Path:
    """A new directory ./jaxsplit-runs/STEM[-k], claimed (a run started in the same second
    with the same scheme holds another one)."""
    for k in range(1, 10_000):
        out = Path(RUNS_DIR) / (stem if k == 1 else f"{stem}-{k}")
        if out.exists():
            continue
        try:
            return outputs.directory(out, "--out directory")
        except _io.OutputBusy:
            continue
    raise InputError(f"no free directory name ./{RUNS_DIR}/{stem}-k; give --out DIR")


def _manifest_inputs(manifest: Path) -> dict:
    try:
        old = json.loads(manifest.read_text())
    except (OSError, ValueError) as err:
        raise InputError(f"cannot resume: {str(manifest)!r} is not a jaxsplit sweep manifest ({err})") from None
    if not (isinstance(old, dict) and isinstance(old.get("inputs"), dict)):
        raise InputError(f"cannot resume: {str(manifest)!r} is not a jaxsplit sweep manifest (a JSON object with "
                         f"an 'inputs' object; got {type(old).__name__})")
    return old["inputs"]


# --------------------------------------------------------------------------- chunk proofs


def _inputs_digest(inputs: dict) -> str:
    text = json.dumps(_metadata.jsonable(inputs), sort_keys=True)
    return hashlib.sha256(f"jaxsplit-sweep-{FORMAT_VERSION}:{text}".encode()).hexdigest()


def _chunk_digest(inputs_digest: str, lo: int, hi: int, cases: dict, results: dict) -> str:
    """SHA-256 over the chunk's inputs digest, case range, cases and results."""
    h = hashlib.sha256(f"{inputs_digest}:{lo}:{hi}".encode())
    for group, arrays in (("case", cases), ("result", results)):
        for key in sorted(arrays):
            a = np.ascontiguousarray(arrays[key])
            h.update(f"{group}:{key}:{a.dtype.str}:{a.shape}".encode())
            h.update(a.tobytes())
    return h.hexdigest()


def _case_slice(cases: dict, lo: int, hi: int) -> dict:
    return {key: np.asarray(v)[lo:hi] for key, v in cases.items()}


def _chunk_arrays(inputs_digest: str, lo: int, hi: int, cases: dict, results: dict) -> dict:
    results = {key: np.asarray(v) for key, v in results.items()}
    proof = {"format": FORMAT_VERSION, "inputs": inputs_digest, "lo": lo, "hi": hi,
             "digest": _chunk_digest(inputs_digest, lo, hi, _case_slice(cases, lo, hi), results)}
    return {"case_index": np.arange(lo, hi), **results, "proof": np.array(json.dumps(proof))}


def _proven_chunk(path: Path, lo: int, hi: int, cases: dict, inputs_digest: str) -> dict | None:
    """The results in ``path`` when its proof holds for these inputs and cases; None when the
    file is absent, unreadable, truncated, edited or unprovable (it is recomputed). A chunk
    proven for OTHER inputs is another sweep's finished work: refused."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {key: z[key] for key in z.files}
        proof = json.loads(str(arrays.pop("proof")))
        index = arrays.pop("case_index")
        claimed = (proof["format"], proof["inputs"], proof["lo"], proof["hi"], proof["digest"])
    except Exception:  # noqa: BLE001 - truncated or foreign file (BadZipFile, KeyError, ...): recompute
        return None
    if claimed[0] == FORMAT_VERSION and claimed[1] != inputs_digest:
        raise InputError(f"{str(path)!r} holds a chunk of a sweep with other inputs; resume with the options "
                         "it was started with, or --force to start over")
    if claimed[:4] != (FORMAT_VERSION, inputs_digest, lo, hi) or not np.array_equal(index, np.arange(lo, hi)):
        return None
    if any(np.ndim(a) == 0 or len(a) != hi - lo for a in arrays.values()):
        return None
    if _chunk_digest(inputs_digest, lo, hi, _case_slice(cases, lo, hi), arrays) != claimed[4]:
        return None
    return arrays


# --------------------------------------------------------------------------- run


def run(args):
    with _io.Outputs(force=args.force) as outputs:
        return _run(args, outputs)


def _run(args, outputs):
    from ..explore._sweep import sweep

    inputs = _inputs(args)
    cases = _bounded_cases(inputs, _bounds.memory_limit(args.max_memory))
    n = len(cases["h"])
    when = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    out, resumed = _prepare_dir(args, outputs, inputs, when)
    digest = _inputs_digest(inputs)
    size = inputs["chunk_cases"]
    n_chunks = math.ceil(n / size)
    bounds = [(k * size, min(n, (k + 1) * size)) for k in range(n_chunks)]
    done = {k for k, (lo, hi) in enumerate(bounds) if _proven_chunk(_chunk_path(out, k), lo, hi, cases, digest)
            is not None}
    if not resumed:
        meta = _metadata.run_metadata("sweep")
        manifest = {"format": FORMAT_VERSION, "inputs": inputs, "inputs_digest": digest, "n_cases": n,
                    "n_chunks": n_chunks, "jaxsplit_version": meta["jaxsplit_version"],
                    "jax_version": meta["jax_version"], "created_utc": meta["created_utc"]}
        outputs.write_npz(out / CASES, cases)
        outputs.write_json(out / MANIFEST, manifest)
    todo = [k for k in range(n_chunks) if k not in done]
    skipped = n_chunks - len(todo)
    if args.resume and not args.quiet and not args.json:
        print(f"resuming {out}: {skipped} of {n_chunks} chunks already done", file=sys.stderr)
    progress = _progress.Progress(n, unit="cases", enabled=not args.quiet)
    start = time.perf_counter()
    done_cases = sum(hi - lo for k, (lo, hi) in enumerate(bounds) if k in done)
    shift = {"shift": _shift(inputs["shift_axis"])} if inputs["split"] == "casimir" else {}
    stop = _signals.current()
    computed = 0
    with stop.defer():  # a signal stops the sweep after the current chunk; finished chunks stay written
        for k in todo:
            if stop.requested:
                break
            lo, hi = bounds[k]
            res = sweep(inputs["scheme"], _case_slice(cases, lo, hi), t_end=inputs["t_end"], split=inputs["split"],
                        **shift, reference_scheme=inputs["reference_scheme"],
                        reference_angle=inputs["reference_angle"], chunk_size=max(1, hi - lo),
                        allow_nonphysical=True)  # the cases' bodies were checked (_cases)
            outputs.write_npz(_chunk_path(out, k), _chunk_arrays(digest, lo, hi, cases, res))
            computed += 1
            done_cases += hi - lo
            progress.update(done_cases)
    if skipped + computed < n_chunks:  # stopped by a signal: the finished chunks are on disk
        progress.close()
        print(f"jaxsplit: interrupted ({stop.signal_name}): {skipped + computed} of {n_chunks} chunks are saved in "
              f"{out}; continue with the same options and --out {out} --resume", file=sys.stderr)
        return _signals.EXIT_INTERRUPTED
    progress.close(done_cases)
    seconds = time.perf_counter() - start
    with stop.critical():
        merged = _merge(outputs, out, cases, bounds, inputs, digest)
        summary = _summary(merged, inputs, n, n_chunks, computed, skipped, seconds, out)
        if not args.no_figure:
            _write_figure(outputs, out, merged, inputs)
            summary["figure"] = str(out / FIGURE)
        outputs.write_json(out / SUMMARY, summary)
        if args.json:
            _metadata.print_json(summary)
        else:
            _print_summary(summary)
    return 0


def _shift(value):
    """The library's 0-based shift from the CLI's 1-based --shift-axis label (or "auto")."""
    return "auto" if value in (None, "auto") else int(value) - 1


def _merge(outputs, out: Path, cases: dict, bounds, inputs: dict, digest: str) -> dict:
    parts = []
    for k, (lo, hi) in enumerate(bounds):
        part = _proven_chunk(_chunk_path(out, k), lo, hi, cases, digest)
        if part is None:
            raise InputError(f"{str(_chunk_path(out, k))!r} changed during the sweep; rerun with --resume")
        parts.append(part)
    results = {f"case_{k}": np.asarray(v) for k, v in cases.items()}
    results |= {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    meta = _metadata.run_metadata("sweep") | {"inputs": inputs, "inputs_digest": digest}
    outputs.write_npz(out / RESULTS, results | {"metadata": _metadata.metadata_array(meta)})
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
        "groups": _groups(r, inputs),
        "seconds": seconds, "out": str(out), "results": str(out / RESULTS),
    }


# --------------------------------------------------------------------------- tables and figure
METRICS = ("error", "energy_error", "casimir_error")


def _group_keys(r, inputs) -> dict:
    """{parameter: (label per case (N,), the labels in order)}: the swept parameters, exact
    groups for a grid, log-spaced bins of each parameter for random samples."""
    ratio = np.stack([r["case_inertia"][:, 1], r["case_inertia"][:, 2]], axis=1)
    h = np.asarray(r["case_h"], dtype=float)
    if inputs["sampling"] == "grid":
        by_ratio = np.array([f"I2/I1={a:g}, I3/I1={b:g}" for a, b in ratio])
        by_h = np.array([f"h={x:g}" for x in h])
        return {"inertia ratios": (by_ratio, list(dict.fromkeys(by_ratio))), "step size": (by_h, list(dict.fromkeys(
            by_h[np.argsort(-h, kind="stable")])))}
    out = {}
    for name, values in (("I2/I1", ratio[:, 0]), ("I3/I1", ratio[:, 1]), ("h", h)):
        edges = np.geomspace(values.min(), values.max() * (1 + 1e-12), RANDOM_BINS + 1)
        k = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, RANDOM_BINS - 1)
        labels = np.array([f"{name} in [{edges[i]:.3g}, {edges[i + 1]:.3g})" for i in k])
        order = [f"{name} in [{edges[i]:.3g}, {edges[i + 1]:.3g})" for i in range(RANDOM_BINS)]
        out[name] = (labels, [o for o in order if o in set(labels)])
    return out


def _groups(r, inputs) -> dict:
    """{parameter: [row per group: cases, median and max of each metric]}."""
    tables = {}
    for parameter, (labels, order) in _group_keys(r, inputs).items():
        rows = []
        for label in order:
            sel = labels == label
            row = {"group": label, "cases": int(sel.sum())}
            for key in METRICS:
                v = np.asarray(r[key], dtype=float)[sel]
                row |= {f"{key}_median": float(np.median(v)), f"{key}_max": float(np.max(v))}
            rows.append(row)
        tables[parameter] = rows
    return tables


def _write_figure(outputs, out, r, inputs):
    from . import _figures

    keys = _group_keys(r, inputs)
    group, order = keys["inertia ratios"] if "inertia ratios" in keys else keys["I3/I1"]
    if inputs["sampling"] == "grid":
        h = np.asarray(inputs["dt"], dtype=float)[np.asarray(r["case_h_index"])]
    else:  # the centre of each case's h bin (geometric)
        edges = np.geomspace(np.min(r["case_h"]), np.max(r["case_h"]) * (1 + 1e-12), RANDOM_BINS + 1)
        k = np.clip(np.searchsorted(edges, r["case_h"], side="right") - 1, 0, RANDOM_BINS - 1)
        h = np.sqrt(edges[k] * edges[k + 1])
    table = {"h": h, "group": group} | {key: np.asarray(r[key]) for key in METRICS}
    title = (f"sweep: {inputs['scheme']} ({inputs['split']} split), {len(h):,} cases to t = {inputs['t_end']:g}, "
             f"{inputs['sampling']} sampling" + (" (h: bin centres)" if inputs["sampling"] == "random" else ""))
    fig = _figures.sweep_figure(table, title=title, order=order)
    outputs.write(out / FIGURE, lambda f: _figures.save_figure(fig, f))


def _print_summary(s):
    print(f"jaxsplit sweep: {s['scheme']} ({s['split']} split), {s['cases']:,} cases to t = {s['t_end']:g} "
          f"in {s['chunks']} chunks ({s['chunks_computed']} computed, {s['chunks_skipped']} resumed) "
          f"in {s['seconds']:.1f} s")
    for key, label in (("energy_error", "max|H/H0 - 1|"), ("casimir_error", "max|C/C0 - 1|"),
                       ("error", "error vs reference"), ("poisson_defect", "Poisson defect")):
        st = s[key]
        print(f"  {label:<20} median {st['median']:.3e}   max {st['max']:.3e}")
    print(f"  reference accuracy   max {s['reference_accuracy_max']:.1e}")
    for parameter, rows in s["groups"].items():
        width = max(len(row["group"]) for row in rows)
        print(f"  {'by ' + parameter:<{width + 2}}  {'cases':>5}   error median / max      energy error median / max")
        for row in rows:
            print(f"    {row['group']:<{width}}  {row['cases']:>5}   {row['error_median']:.2e} / {row['error_max']:.2e}"
                  f"     {row['energy_error_median']:.2e} / {row['energy_error_max']:.2e}")
    print(f"  wrote {s['results']}, {Path(s['out']) / SUMMARY}" + (f" and {s['figure']}" if s.get("figure") else ""))
