"""``jaxsplit fit --system spin-lattice``: a spin lattice's couplings from an observed trajectory
or S(q, ω) (``jaxsplit.fit_couplings``).

The lattice and the starting couplings are parsed as ``simulate --system spin-lattice``
parses them (``_spin_simulate``: ``--lattice``, ``--size``, ``--open``, ``--exchange``,
``--anisotropic``, ``--dm``, ``--anisotropy``, ``--axis``, ``--field``, ``--spin-length``);
the lattice defaults to the one the data file's metadata names (what ``simulate --out``
wrote), never its couplings. ``--fit`` names the fitted terms (their options give the
start); every other term is held at its option's value. The data file (.npz): ``t`` (n,)
and ``spins`` (n, *lattice shape, 3) (a trajectory; with ``--target structure-factor`` its
S(q, ω) is the data and its first state the initial state), or ``t``, ``intensity``
(*size, n) and ``x0`` (N, 3) (an observed S(q, ω)).

Outputs: the JSON summary (``--json`` on stdout; ``--out FILE.json`` through the one
writer ``_io.Outputs``).
"""

import sys

import numpy as np

from ..core._errors import InputError
from . import _args, _bounds, _data, _io, _metadata, _signals, _spin_simulate

TERMS = ("exchange", "anisotropic", "dm", "anisotropy", "field")
OPTION = {"exchange": "--exchange", "anisotropic": "--anisotropic", "dm": "--dm", "anisotropy": "--anisotropy",
          "field": "--field"}
DEFAULT_FIT = "exchange,field"
SIMULATE_ONLY = {"initial": "--initial", "amplitude": "--amplitude", "method": "--method"}


def add_arguments(p) -> None:
    """The spin-lattice options on fit's parser: simulate's lattice and coupling options, and
    the fit's own."""
    import argparse

    _spin_simulate.add_arguments(p, None)
    for action in p._actions:  # simulate's initial state and method: parsed, refused, not advertised
        if action.dest in SIMULATE_ONLY:
            action.help = argparse.SUPPRESS
    g = p.add_argument_group("spin-lattice fit (--system spin-lattice)")
    g.add_argument("--fit", type=_args.names("--fit"), default=None, metavar="TERMS",
                   help=f"fitted terms among {','.join(TERMS)} (default {DEFAULT_FIT}); their options give the "
                        "start, the other terms are held at their options' values")
    g.add_argument("--bond-classes", choices=("direction", "all"), default=None,
                   help="one exchange per bond direction, or one for all bonds (default direction)")
    g.add_argument("--target", choices=("trajectory", "structure-factor"), default=None,
                   help="compare the spins (default) or S(q, w)")
    g.add_argument("--resolution", type=_args.nonnegative_float, default=None, metavar="W",
                   help="structure-factor: Gaussian broadening in w (default 4 dw)")
    g.add_argument("--adjoint", choices=("reversible", "checkpoint"), default=None,
                   help="what the gradient stores: reversible (memory flat in the steps; default) or checkpoint")
    g.add_argument("--out", default=None, metavar="FILE.json", help="also write the summary to this file")
    g.add_argument("--force", action="store_true", default=None, help="overwrite --out")


OWN_FIT = {"fit": "--fit", "bond_classes": "--bond-classes", "target": "--target", "resolution": "--resolution",
           "adjoint": "--adjoint", "out": "--out", "force": "--force"}


def refuse_stray(args) -> None:
    """Spin-lattice options to another system, and simulate-only options here: one line."""
    own = {**_spin_simulate.OWN, **OWN_FIT}
    if args.system != "spin-lattice":
        given = [flag for dest, flag in own.items() if getattr(args, dest, None) is not None]
        if given:
            raise InputError(f"{', '.join(given)} appl(ies) only to --system spin-lattice")
        return
    given = [flag for dest, flag in SIMULATE_ONLY.items() if getattr(args, dest, None) is not None]
    given += [f"--{k.replace('_', '-')}" for k in ("energy", "inertia1", "weight") if getattr(args, k) is not None]
    if args.fixed_m0:
        given.append("--fixed-m0")
    if given:
        raise InputError(f"{', '.join(given)} do(es) not apply to fit --system spin-lattice (the initial state is the "
                         "data's first state)")


def _lattice(args, meta):
    import jaxsplit

    written = meta.get("system")
    if written is not None and written != "spin-lattice":
        raise InputError(f"{args.data} holds a {written} run, not a spin lattice")
    name = args.lattice or meta.get("lattice")
    size = args.size or meta.get("size")
    if name is None or size is None:
        raise InputError(f"{args.data} does not name its lattice (no metadata): give --lattice and --size")
    if isinstance(size, list):
        size = "x".join(str(int(s)) for s in size)
    periodic = (not args.open) if args.open is not None else bool(meta.get("periodic", True))
    return jaxsplit.lattices.lattice(name, size, periodic=periodic)


def _terms(args):
    names = args.fit or DEFAULT_FIT.split(",")
    bad = [n for n in names if n not in TERMS]
    if bad:
        raise InputError(f"--fit {','.join(names)}: unknown term {bad[0]!r}; allowed: {', '.join(TERMS)}")
    if len(set(names)) != len(names):
        raise InputError(f"--fit {','.join(names)} names a term twice")
    values = {k: _spin_simulate._value(args, k) for k in TERMS}
    values["dm"] = args.dm
    if "dm" in names and values["dm"] is None:
        values["dm"] = (0.0, 0.0, 0.0)
    start = {k: values[k] for k in names}
    fixed = {k: v for k, v in values.items() if k not in names and v is not None}
    return start, fixed


def _observations(args, lat, arrays, target):
    """(t, observed, x0) from the file, checked."""
    if "t" not in arrays:
        raise InputError(f"{args.data}: missing array 't' (n,)")
    t = np.asarray(arrays["t"])
    if not np.issubdtype(t.dtype, np.number) or np.iscomplexobj(t) or t.ndim != 1 or len(t) < 4:
        raise InputError(f"{args.data}: t must be real times of shape (n,) with n >= 4, got {t.dtype} {t.shape}")
    t = t.astype(float)
    if "spins" in arrays:
        spins = np.asarray(arrays["spins"])
        if np.iscomplexobj(spins) or not np.issubdtype(spins.dtype, np.number) or spins.shape[0] != len(t) or \
                spins.size != len(t) * lat.n_sites * 3 or spins.shape[-1] != 3:
            raise InputError(f"{args.data}: spins must have shape ({len(t)}, {', '.join(map(str, lat.shape))}, 3) for "
                             f"this {lat.name} lattice, got {spins.shape}")
        spins = spins.astype(float).reshape(len(t), lat.n_sites, 3)
        if not np.all(np.isfinite(spins)):
            raise InputError(f"{args.data}: spins must be finite")
        if target == "trajectory":
            return t, spins, None
        import jaxsplit

        dt = np.diff(t)
        if not np.allclose(dt, dt[0], rtol=1e-9, atol=0):
            raise InputError(f"{args.data}: --target structure-factor needs equally spaced times")
        return t, np.asarray(jaxsplit.structure_factor(spins, lat, float(dt[0])).intensity), spins[0]
    if "intensity" in arrays:
        if target != "structure-factor":
            raise InputError(f"{args.data} holds an S(q, w) (intensity): give --target structure-factor")
        if "x0" not in arrays:
            raise InputError(f"{args.data}: an S(q, w) file needs x0 ({lat.n_sites}, 3), the initial state")
        return t, np.asarray(arrays["intensity"], float), np.asarray(arrays["x0"], float)
    raise InputError(f"{args.data}: expected spins (n, *lattice shape, 3) or intensity (*size, n) with x0")


def run(args) -> int:
    from ..explore._fit_spins import fit_couplings
    from ..explore._fit import substeps

    refuse_stray(args)
    with _io.Outputs(force=bool(args.force)) as outputs:
        out = outputs.file(args.out, "fit summary") if args.out else None
        arrays, meta = _data.read(args.data)
        lat = _lattice(args, meta)
        target = args.target or "trajectory"
        t, observed, x0 = _observations(args, lat, arrays, target)
        if np.all(np.diff(t) > 0):  # else the library names the problem
            from .fit import MAX_MODEL_STEPS

            _bounds.at_most((len(t) - 1) * substeps(t, args.max_step) * lat.n_sites, MAX_MODEL_STEPS * 100,
                            "the model's spin-steps per evaluation ((n - 1) intervals x steps x spins)",
                            "every iteration runs them forward and backward", "use a larger --max-step or fewer states")
        start, fixed = _terms(args)
        scheme_name = args.scheme or "strang"
        scheme = _bounds.scheme(scheme_name)
        res = fit_couplings(lat, t, observed, start, fixed=fixed, classes=args.bond_classes or "direction",
                            axis=_spin_simulate._value(args, "axis"),
                            spin_length=_spin_simulate._value(args, "spin_length"), target=target, x0=x0,
                            resolution=args.resolution, scheme=scheme, max_step=args.max_step,
                            adjoint=args.adjoint or "reversible")
        summary = {"command": "fit", "system": "spin-lattice", "lattice": lat.name, "size": list(lat.size),
                   "periodic": lat.periodic, "n_sites": lat.n_sites, "observations": len(t), "scheme": scheme_name,
                   "max_step": args.max_step, "data": args.data, **res.as_dict()}
        if out is not None:
            outputs.write_json(out, {**_metadata.run_metadata("fit"), **summary})
            summary["out"] = str(out)
    with _signals.current().critical():
        if args.json:
            _metadata.print_json(summary)
        else:
            _print(summary)
    return 0


def _print(s):
    print(f"spin-lattice fit ({s['target']}) of {s['observations']} observations on {s['lattice']} "
          f"{'x'.join(map(str, s['size']))} in {s['seconds']:.1f} s, {s['iterations']} iterations, "
          f"loss {s['loss']:.3e}, noise sigma {s['noise_sigma']:.3e}")
    for k, v in s["couplings"].items():
        print(f"  {k} = {v} +- {s['couplings_std'][k]}")
    if s["classes"] != ["all"]:
        print(f"  bond classes: {', '.join(s['classes'])}")
    for line in s["gauge"]:
        print(f"  gauge: {line}")
    for kind in ("undetermined", "weak"):
        for c in s[kind]:
            print(f"  {kind}: {c['combination']} (eigenvalue ratio {c['eigenvalue_ratio']:.1e})")
    if "out" in s:
        print(f"  out: {s['out']}", file=sys.stdout)
