"""``jaxsplit fit``: recover inertia ratios from an observed trajectory (obs.npz: t, m).

m(t) determines only the differences 1/I_i − 1/I_j; one more number fixes the rest: the
kinetic energy (``--energy`` or an ``energy`` entry in the file) or I1 (``--inertia1`` or
an ``inertia1`` entry). Without either, I1 = 1 is assumed and the output says so.

The data file is checked whole before anything compiles (an ``.npz`` with real, finite t
(n,) strictly increasing and m (n, 3); data that determine no inertia are refused by the
library), and the model's work is bounded (``MAX_MODEL_STEPS`` per evaluation). Nothing
finished would be lost by stopping a fit part-way, so SIGINT/SIGTERM end it at once
(exit 130); the result, once computed, is printed whole.
"""

import json
import math
import zipfile

import numpy as np

from ..core._errors import InputError
from ..explore._fit import substeps
from ..explore._fit_inertia import fit_inertia
from . import _args, _bounds, _metadata, _signals

# Each Adam or L-BFGS iteration runs the model forward and backward; at 10^6 model steps per
# evaluation a fit already takes hours on a CPU core.
MAX_MODEL_STEPS = 10**6

EXAMPLES = """examples:
  jaxsplit fit --data obs.npz                    # assumes I1 = 1 and says so
  jaxsplit fit --data obs.npz --energy 0.65 --energy-sigma 1e-3 --json
  jaxsplit fit --data obs.npz --inertia1 2.0 --scheme strang --max-step 0.02
obs.npz: t (n,) increasing times, m (n, 3) observed body angular momenta; optional
scalars energy and inertia1. Exit status 2 for a malformed file (one line)."""


def add_parser(sub):
    import argparse

    p = sub.add_parser("fit", help="fit inertia ratios to an observed trajectory",
                       description=__doc__.split(": ", 1)[1].replace("``", ""), epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="obs.npz holding t (n,) and m (n, 3)")
    p.add_argument("--energy", type=_args.positive_float, default=None, help="known kinetic energy (fixes the gauge)")
    p.add_argument("--energy-sigma", type=_args.nonnegative_float, default=0.0, help="standard deviation of --energy")
    p.add_argument("--inertia1", type=_args.positive_float, default=None, help="known I1 (fixes the gauge)")
    p.add_argument("--scheme", default="kahan-li-6", help="integrator of the model (Casimir split)")
    p.add_argument("--max-step", type=_args.positive_float, default=0.05, help="largest model step")
    p.add_argument("--fixed-m0", action="store_true", help="take m0 = the first observation")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _scalar(data, key):
    if key not in data:
        return None
    arr = np.asarray(data[key])
    if arr.size != 1 or not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"{key!r} in the data file must be one number, got shape {arr.shape}")
    value = float(arr.reshape(()))
    if not math.isfinite(value):
        raise InputError(f"{key!r} in the data file must be finite, got {value}")
    return value


def load_observations(path: str):
    """(t, m, energy | None, inertia1 | None) from an .npz file; malformed -> InputError."""
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError as err:
        raise InputError(f"no such data file: {path}") from err
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise InputError(f"{path} is not a readable .npz file ({type(err).__name__})") from err
    if not isinstance(data, np.lib.npyio.NpzFile):  # an .npy file: one bare array
        raise InputError(f"{path} holds a single array (.npy); expected an .npz holding t (n,) and m (n, 3)")
    try:
        with data:
            missing = [k for k in ("t", "m") if k not in data.files]
            if missing:
                raise InputError(f"{path}: missing array(s) {missing}; expected t (n,) and m (n, 3)")
            t, m = np.asarray(data["t"]), np.asarray(data["m"])
            energy, inertia1 = _scalar(data, "energy"), _scalar(data, "inertia1")
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        if isinstance(err, InputError):
            raise
        raise InputError(f"{path} is not a readable .npz file ({type(err).__name__})") from err
    for name, arr in (("t", t), ("m", m)):
        if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
            raise InputError(f"{path}: {name} must be real numbers (numeric, not complex), got dtype {arr.dtype}")
    if t.ndim != 1:
        raise InputError(f"{path}: t must have shape (n,), got {t.shape}")
    if m.shape != (len(t), 3):
        raise InputError(f"{path}: m must have shape ({len(t)}, 3), got {m.shape}")
    for name, arr in (("t", t), ("m", m)):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{path}: {name} must be finite, found {int(np.sum(~np.isfinite(arr)))} NaN/inf")
    return t, m, energy, inertia1


def run(args):
    t, m, energy, inertia1 = load_observations(args.data)
    scheme = _bounds.scheme(args.scheme)
    if len(t) >= 2 and np.all(np.diff(t) > 0):  # else fit_inertia names the problem
        _bounds.at_most((len(t) - 1) * substeps(t, args.max_step), MAX_MODEL_STEPS,
                        "the model's steps per evaluation ((n - 1) intervals x ceil(longest interval / --max-step))",
                        "every iteration runs them forward and backward", "use a larger --max-step")
    energy = args.energy if args.energy is not None else energy
    inertia1 = args.inertia1 if args.inertia1 is not None else inertia1
    if args.energy is not None and args.inertia1 is None:
        inertia1 = None
    elif args.inertia1 is not None and args.energy is None:
        energy = None
    res = fit_inertia(t, m, energy=energy, energy_sigma=args.energy_sigma, inertia1=inertia1,
                      fit_m0=not args.fixed_m0, scheme=scheme, max_step=args.max_step)
    with _signals.current().critical():  # the fit is done: print it whole
        _print(args, res, t)
    return 0


def _print(args, res, t):
    if args.json:
        out = {
            "inertia_ratios": res.inertia_ratios.tolist(),
            "ratio_std": res.ratio_std.tolist(),
            "inertia": res.inertia.tolist(),
            "inverse_inertia_differences": res.inverse_differences.tolist(),
            "inverse_inertia_differences_std": res.inverse_differences_std.tolist(),
            "m0": res.m0.tolist(),
            "loss": res.loss,
            "noise_sigma": res.noise_sigma,
            "iterations": res.iterations,
            "gauge": res.gauge,
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
    print(f"  gauge: {res.gauge}")
    print(f"  I2/I1 = {r[0]:.6f} +- {s[0]:.2e}    I3/I1 = {r[1]:.6f} +- {s[1]:.2e}")
    print(f"  identifiable: 1/I1 - 1/I3 = {res.inverse_differences[0]:.6f}, "
          f"1/I2 - 1/I3 = {res.inverse_differences[1]:.6f}")
    lo, hi = res.ratio_range
    print(f"  from m(t) alone (any positive gauge): I2/I1 in [{lo[0]:.4g}, {lo[1]:.4g}], "
          f"I3/I1 in [{hi[0]:.4g}, {hi[1]:.4g}]")
