"""``jaxsplit fit``: recover a body's parameters from an observed trajectory (a file in the
format ``simulate`` writes, read by ``_data``: .npz or .csv).

Free rigid body (t, m): m(t) determines only the differences 1/I_i − 1/I_j; one more
number fixes the rest (the gauge): the kinetic energy (``--energy``, or the file's
``energy``: a number, or one per state of which the first is used, as ``simulate`` writes
it) or I1 (``--inertia1`` or the file's ``inertia1``); an option overrides the file.
Without either, I1 = 1 is assumed and the output says so: the ratios are then not
measured, and no uncertainty is printed for them (only for the differences, which are).

Heavy top (t, m, Γ): the inertia is determined by (m, Γ) (Γ̇ = Γ × I⁻¹m fixes every 1/I_i),
the centre of mass only through weight·χ, so χ is reported for the weight of ``--weight``
(else the file's metadata, else 1, assumed and said so). The fit is the generic
``jaxsplit.fit`` on a heavy-top family started from integral matching (a linear least
squares on the trapezoid rule); parameters the data leave undetermined (a null direction
of the Gauss–Newton Hessian) are reported as such, without an uncertainty.

The data file is checked whole before anything compiles (real, finite t (n,) strictly
increasing and m (n, 3); data that determine no inertia are refused by the library), and
the model's work is bounded (``MAX_MODEL_STEPS`` per evaluation). Nothing finished would be
lost by stopping a fit part-way, so SIGINT/SIGTERM end it at once (exit 130); the result,
once computed, is printed whole.
"""

import json
import math
import sys

import numpy as np

from ..core._errors import InputError
from ..explore._fit import substeps
from ..explore._fit_inertia import fit_inertia
from . import _args, _bounds, _data, _metadata, _signals, _spin_fit

# Each Adam or L-BFGS iteration runs the model forward and backward; at 10^6 model steps per
# evaluation a fit already takes hours on a CPU core.
MAX_MODEL_STEPS = 10**6
# A Gauss–Newton eigenvalue below this fraction of the largest is a direction the data do not fix.
NULL_RATIO = 1e-10

# Each fit integrates the model from its fitted initial state (3 numbers) through the times: fewer
# than this many observations cannot test it (jaxsplit.fit_inertia refuses them as well).
MIN_OBSERVATIONS = 4

DESCRIPTION = (f"Recover a body's parameters from an observed trajectory: a .npz or .csv file in the format "
               f"`jaxsplit simulate --out` writes, with at least {MIN_OBSERVATIONS} observation times.")

EXAMPLES = """examples:
  jaxsplit fit --data obs.npz                    # free body; the file's energy (if any) fixes the gauge
  jaxsplit fit --data obs.csv --energy 0.65 --energy-sigma 1e-3 --json
  jaxsplit fit --data obs.npz --inertia1 2.0 --scheme strang --max-step 0.02
  jaxsplit fit --data top.npz --weight 1          # heavy top (the file has gamma): inertia and centre of mass
  jaxsplit fit --system spin-lattice --data spins.npz --fit exchange,field --exchange 0.9 --json
data: the format `jaxsplit simulate --out` writes (.npz or .csv): t (n,) increasing times, m (n, 3)
observed body angular momenta, gamma (n, 3) for a heavy top; optional energy (a number, or one per
state: the first is used) and inertia1. Exit status 2 for a malformed file (one line)."""


def add_parser(sub):
    import argparse

    p = sub.add_parser("fit", help="fit inertia (and a heavy top's centre of mass) to an observed trajectory",
                       description=DESCRIPTION, epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="trajectory file (.npz or .csv, as `jaxsplit simulate` writes)")
    p.add_argument("--system", choices=("auto", "rigid-body", "heavy-top"), default="auto",
                   help="model (default auto: heavy-top when the file has gamma, else rigid-body)")
    p.add_argument("--energy", type=_args.positive_float, default=None,
                   help="rigid-body: known kinetic energy (fixes the gauge; overrides the file)")
    p.add_argument("--energy-sigma", type=_args.nonnegative_float, default=0.0, help="standard deviation of --energy")
    p.add_argument("--inertia1", type=_args.positive_float, default=None,
                   help="rigid-body: known I1 (fixes the gauge; overrides the file)")
    p.add_argument("--weight", type=_args.positive_float, default=None,
                   help="heavy-top: weight M g of the top (only weight x centre of mass is observable; default: "
                        "the file's metadata, else 1, assumed)")
    p.add_argument("--scheme", default=None,
                   help="integrator of the model (default kahan-li-6; strang for --system spin-lattice)")
    p.add_argument("--max-step", type=_args.positive_float, default=0.05, help="largest model step (default 0.05)")
    p.add_argument("--fixed-m0", action="store_true", help="take the initial state = the first observation")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _spin_fit.add_arguments(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------- data


def _scalar(arrays, key, path, n):
    """A gauge value in the file: one number, or one per state (the first is used: it is conserved)."""
    if key not in arrays:
        return None
    arr = np.asarray(arrays[key])
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr) or (arr.size != 1 and arr.shape != (n,)):
        raise InputError(f"{key!r} in the data file must be one number or one per observation ({n}), got shape "
                         f"{arr.shape}")
    value = float(arr.reshape(-1)[0])
    if not math.isfinite(value):
        raise InputError(f"{key!r} in the data file must be finite, got {value}")
    return value


def load_observations(path: str):
    """(t, {"m": (n, 3), "gamma": (n, 3) if present}, energy | None, inertia1 | None, metadata)."""
    arrays, meta = _data.read(path)
    missing = [k for k in ("t", "m") if k not in arrays]
    if missing:
        raise InputError(f"{path}: missing array(s) {missing}; expected t (n,) and m (n, 3)")
    t = np.asarray(arrays["t"])
    states = {k: np.asarray(arrays[k]) for k in ("m", "gamma") if k in arrays}
    for name, arr in (("t", t), *states.items()):
        if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
            raise InputError(f"{path}: {name} must be real numbers (numeric, not complex), got dtype {arr.dtype}")
    if t.ndim != 1:
        raise InputError(f"{path}: t must have shape (n,), got {t.shape}")
    for name, arr in states.items():
        if arr.shape != (len(t), 3):
            raise InputError(f"{path}: {name} must have shape ({len(t)}, 3), got {arr.shape}")
    for name, arr in (("t", t), *states.items()):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{path}: {name} must be finite, found {int(np.sum(~np.isfinite(arr)))} NaN/inf")
    if len(t) < MIN_OBSERVATIONS:
        raise InputError(f"{path}: {len(t)} observation time{'s' if len(t) != 1 else ''}; fit needs at least "
                         f"{MIN_OBSERVATIONS} (e.g. jaxsplit simulate --save-at 0.5,1,1.5,2,2.5,3 --out FILE)")
    energy, inertia1 = (_scalar(arrays, k, path, len(t)) for k in ("energy", "inertia1"))
    return t, states, energy, inertia1, meta


# --------------------------------------------------------------------------- run


MODELS = {"rigid-body": "rigid-body", "attitude": "rigid-body", "heavy-top": "heavy-top"}  # file's system -> model


def run(args):
    _spin_fit.refuse_stray(args)
    if args.system == "spin-lattice":
        return _spin_fit.run(args)
    args.scheme = args.scheme or "kahan-li-6"
    t, states, energy, inertia1, meta = load_observations(args.data)
    written_by = meta.get("system")
    if written_by == "spin-lattice":
        raise InputError(f"{args.data} holds a spin-lattice run: give --system spin-lattice")
    if args.system == "auto" and written_by is not None and written_by not in MODELS:
        raise InputError(f"{args.data} holds a {written_by} run; fit models the free body and the heavy top (give "
                         "--system rigid-body to fit its m(t) as a free body's)")
    system = args.system if args.system != "auto" else ("heavy-top" if "gamma" in states else "rigid-body")
    if written_by == "attitude" and system == "rigid-body":
        print("jaxsplit: note: the file's attitude Q is not used: m(t) determines what the fit can know",
              file=sys.stderr)
    scheme = _bounds.scheme(args.scheme)
    if len(t) >= 2 and np.all(np.diff(t) > 0):  # else the library names the problem
        _bounds.at_most((len(t) - 1) * substeps(t, args.max_step), MAX_MODEL_STEPS,
                        "the model's steps per evaluation ((n - 1) intervals x ceil(longest interval / --max-step))",
                        "every iteration runs them forward and backward", "use a larger --max-step")
    if system == "heavy-top":
        return _run_heavy_top(args, t, states, meta, scheme)
    if args.weight is not None:
        raise InputError("--weight applies to a heavy-top fit (the file has no gamma, or --system rigid-body)")
    if "gamma" in states:
        print("jaxsplit: note: --system rigid-body fits m(t) only; the file's gamma is not used", file=sys.stderr)
    if args.energy is not None and args.inertia1 is not None:
        raise InputError("give --energy or --inertia1 (one gauge), not both")
    source = None
    if args.energy is not None:  # an option overrides the file's gauge (of either kind)
        energy, inertia1, source = args.energy, None, "--energy"
    elif args.inertia1 is not None:
        energy, inertia1, source = None, args.inertia1, "--inertia1"
    elif energy is not None:  # the file's energy wins over its inertia1: it is what simulate writes
        inertia1, source = None, _file_energy_source(args.data, meta)
    elif inertia1 is not None:
        source = f"the file's inertia1 ({args.data})"
    with_energy = "with an energy gauge (--energy, or an energy in the data file)"
    _args.refuse_unused(args, {"energy_sigma": (energy is not None, with_energy)})
    res = fit_inertia(t, states["m"], energy=energy, energy_sigma=args.energy_sigma, inertia1=inertia1,
                      fit_m0=not args.fixed_m0, scheme=scheme, max_step=args.max_step)
    with _signals.current().critical():  # the fit is done: print it whole
        _print(args, res, t, source)
    return 0


def _file_energy_source(path, meta) -> str:
    """Where a file's energy came from, in words: simulate computes it from the states before
    any --noise, so it is exact only for synthetic data (and its sigma 0 means just that)."""
    if meta.get("command") == "simulate":
        noisy = f" before its --noise {meta['noise']:g} was added" if meta.get("noise") else ""
        return (f"the file's energy ({path}), computed by jaxsplit simulate from its states{noisy}: exact "
                "only for synthetic data; for measured data give --energy E --energy-sigma S")
    return f"the file's energy ({path}), taken as exact (--energy-sigma S gives its uncertainty)"


def _assumed(res) -> bool:
    return res.gauge.startswith("ASSUMED")


def _gauge_text(res) -> str:
    """The library's gauge line in the command line's words."""
    return res.gauge.replace("pass energy= or inertia1=", "pass --energy or --inertia1")


def _print(args, res, t, source=None):
    assumed = _assumed(res)
    if args.json:
        out = {
            "system": "rigid-body",
            "inertia_ratios": res.inertia_ratios.tolist(),
            # null: the ratios are not measured without a gauge (they follow from the assumed one)
            "ratio_std": None if assumed else res.ratio_std.tolist(),
            "inertia": res.inertia.tolist(),
            "inverse_inertia_differences": res.inverse_differences.tolist(),
            "inverse_inertia_differences_std": res.inverse_differences_std.tolist(),
            "m0": res.m0.tolist(),
            "loss": res.loss,
            "noise_sigma": res.noise_sigma,
            "iterations": res.iterations,
            "gauge": _gauge_text(res),
            "gauge_assumed": assumed,
            "gauge_source": source,
            # null = unbounded (JSON has no infinity)
            "ratio_range_from_m_alone": [[v if math.isfinite(v) else None for v in row]
                                         for row in res.ratio_range.tolist()],
            "seconds": res.seconds,
        }
        print(json.dumps(_metadata.jsonable(out), allow_nan=False))
        return
    r, s = res.inertia_ratios, res.ratio_std
    print(f"fit of {len(t)} observations over t in [{t[0]:g}, {t[-1]:g}] in {res.seconds:.1f} s, "
          f"{res.iterations} iterations, loss {res.loss:.3e}, noise sigma {res.noise_sigma:.3e}")
    d, ds = res.inverse_differences, res.inverse_differences_std
    print(f"  measured: 1/I1 - 1/I3 = {d[0]:.6f} +- {ds[0]:.2e}, 1/I2 - 1/I3 = {d[1]:.6f} +- {ds[1]:.2e}")
    print(f"  gauge: {_gauge_text(res)}" + (f", from {source}" if source else ""))
    lo, hi = res.ratio_range
    if assumed:
        print(f"  I2/I1 = {r[0]:.6f}, I3/I1 = {r[1]:.6f} under the assumed gauge: not measured (no uncertainty); "
              f"m(t) alone allows I2/I1 in [{lo[0]:.4g}, {lo[1]:.4g}], I3/I1 in [{hi[0]:.4g}, {hi[1]:.4g}]")
    else:
        print(f"  I2/I1 = {r[0]:.6f} +- {s[0]:.2e}    I3/I1 = {r[1]:.6f} +- {s[1]:.2e}")
        print(f"  from m(t) alone (any positive gauge): I2/I1 in [{lo[0]:.4g}, {lo[1]:.4g}], "
              f"I3/I1 in [{hi[0]:.4g}, {hi[1]:.4g}]")


# --------------------------------------------------------------------------- heavy top


def heavy_top_family(params):
    """HeavyTop(exp(log_inertia), weight·χ, weight 1): only the product enters the equations."""
    import jax.numpy as jnp

    from ..systems._heavy_top import HeavyTop

    return HeavyTop(jnp.exp(params["log_inertia"]), params["moment"], 1.0, allow_nonphysical=True)  # a fit roams


PARAMETERS = ("1/I1", "1/I2", "1/I3", "weight x centre of mass x", "weight x centre of mass y",
              "weight x centre of mass z")
DEGENERATE = 1e-12  # a singular value of the integral-matching system at round-off: exactly undetermined


def _matching_system(t, m, gamma):
    """The integral-matching least squares (lhs (6(n-1), 6), rhs): d(m, Γ)/dt = M (1/I, weight·χ),
    by the trapezoid rule over each interval."""
    eye = np.eye(3)

    def rows(mk, gk):  # (n, 6, 6): d(m, Γ)/dt = M (w, μ)
        a = np.stack([mk[:, i, None] * np.cross(mk, eye[i]) for i in range(3)], axis=-1)
        b = np.stack([mk[:, i, None] * np.cross(gk, eye[i]) for i in range(3)], axis=-1)
        hat_g = np.stack([np.cross(gk, eye[j]) for j in range(3)], axis=-1)
        top = np.concatenate([a, hat_g], axis=-1)
        bottom = np.concatenate([b, np.zeros_like(b)], axis=-1)
        return np.concatenate([top, bottom], axis=-2)

    dt = np.diff(t)[:, None, None]
    lhs = (0.5 * dt * (rows(m[:-1], gamma[:-1]) + rows(m[1:], gamma[1:]))).reshape(-1, 6)
    rhs = np.concatenate([np.diff(m, axis=0), np.diff(gamma, axis=0)], axis=1).reshape(-1)
    return lhs, rhs


def _refuse_undetermined(path, t, m, gamma):
    """Refuse data that leave a parameter exactly undetermined (the fit would print a number for
    it): a null direction of the integral-matching system, to round-off."""
    lhs, _ = _matching_system(t, m, gamma)
    _, sv, vt = np.linalg.svd(lhs / max(np.max(np.abs(lhs)), 1e-300))
    null = vt[sv <= DEGENERATE * max(sv[0], 1e-300)]
    if not null.size:
        return
    names = [PARAMETERS[k] for k in range(6) if np.any(np.abs(null[:, k]) > 0.1)]
    why = ("gamma is 0 at every observation (gamma is the unit vertical seen from the body)"
           if not np.any(gamma) else "gamma(t) and m(t) leave a direction of the parameters free")
    raise InputError(f"{path}: these data do not determine {', '.join(names)}: {why}; nothing fitted")


def heavy_top_start(t, m, gamma):
    """(1/I, weight·χ) by integral matching: ṁ = m × (w ⊙ m) + Γ × μ and Γ̇ = Γ × (w ⊙ m) are
    linear in (w, μ); the trapezoid rule over each interval gives a least-squares problem."""
    lhs, rhs = _matching_system(t, m, gamma)
    theta, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
    w = theta[:3]
    w = np.where(w > 1e-3 * np.max(np.abs(w)), w, 1e-3 * np.max(np.abs(w)) or 1.0)  # positive moments to start
    return w, theta[3:]


def _weight(args, meta):
    if args.weight is not None:
        return args.weight, f"--weight {args.weight:g}"
    if meta.get("system") == "heavy-top" and isinstance(meta.get("weight"), (int, float)) and meta["weight"] > 0:
        return float(meta["weight"]), f"the file's weight {meta['weight']:g}"
    return 1.0, "ASSUMED weight 1 (only weight x centre of mass is observable; pass --weight)"


def _run_heavy_top(args, t, states, meta, scheme):
    import jax.numpy as jnp

    from ..explore._fit import fit

    if "gamma" not in states:
        raise InputError(f"--system heavy-top needs gamma (n, 3) in {args.data} (the vertical seen from the body)")
    for option in ("energy", "inertia1"):
        if getattr(args, option) is not None:
            raise InputError(f"--{option} applies to a rigid-body fit; a heavy top's inertia is determined by "
                             "(m, gamma) without a gauge")
    weight, weight_note = _weight(args, meta)
    m, gamma = states["m"], states["gamma"]
    if not np.all(np.diff(t) > 0):
        raise InputError(f"{args.data}: t must be strictly increasing")
    _refuse_undetermined(args.data, t, m, gamma)
    w0, moment0 = heavy_top_start(t, m, gamma)
    params0 = {"log_inertia": jnp.log(1 / jnp.asarray(w0)), "moment": jnp.asarray(moment0)}
    res = fit(heavy_top_family, t, (m, gamma), params0, fit_x0=not args.fixed_m0, scheme=scheme, split="axes",
              max_step=args.max_step)
    inertia = np.exp(res.params["log_inertia"])
    inertia_std = inertia * res.params_std["log_inertia"]
    moment, moment_std = np.asarray(res.params["moment"]), np.asarray(res.params_std["moment"])
    # Parameters along a near-null direction of the Gauss–Newton Hessian are not determined.
    evals, vecs = res.hessian_eigenvalues, res.null_directions
    null = vecs[:, evals < NULL_RATIO * max(evals[-1], 1e-300)]
    undetermined = np.any(np.abs(null) > 0.1, axis=1)[:6] if null.size else np.zeros(6, bool)
    out = {
        "system": "heavy-top",
        "inertia": inertia.tolist(),
        "inertia_std": [None if u else float(s) for u, s in zip(undetermined[:3], inertia_std)],
        "center_of_mass": (moment / weight).tolist(),
        "center_of_mass_std": [None if u else float(s / weight) for u, s in zip(undetermined[3:], moment_std)],
        "weight": weight, "weight_source": weight_note,
        "weight_times_center_of_mass": moment.tolist(),
        "m0": np.asarray(res.x0[0]).tolist() if isinstance(res.x0, tuple) else None,
        "gamma0": np.asarray(res.x0[1]).tolist() if isinstance(res.x0, tuple) else None,
        "loss": res.loss, "noise_sigma": res.noise_sigma, "iterations": res.iterations,
        "hessian_eigenvalues": evals.tolist(), "seconds": res.seconds,
    }
    with _signals.current().critical():
        if args.json:
            print(json.dumps(_metadata.jsonable(out), allow_nan=False))
        else:
            _print_heavy_top(out, t)
    return 0


def _pm(value, std):
    return f"{value:.6f} +- {std:.2e}" if std is not None else f"{value:.6f} (not determined by the data)"


def _print_heavy_top(out, t):
    print(f"heavy-top fit of {len(t)} observations over t in [{t[0]:g}, {t[-1]:g}] in {out['seconds']:.1f} s, "
          f"{out['iterations']} iterations, loss {out['loss']:.3e}, noise sigma {out['noise_sigma']:.3e}")
    for k in range(3):
        print(f"  I{k + 1} = {_pm(out['inertia'][k], out['inertia_std'][k])}")
    print(f"  weight: {out['weight_source']}")
    for k, axis in enumerate("xyz"):
        print(f"  centre of mass {axis} = {_pm(out['center_of_mass'][k], out['center_of_mass_std'][k])}")
