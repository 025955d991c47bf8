"""``jaxsplit simulate --system spin-lattice``: classical spins on a lattice, with the figures a
magnetism user expects and the JSON summary.

Its own options (``add_arguments``; refused for the other systems, and theirs for it):
the lattice (``--lattice``, ``--size``, ``--open``), the couplings of
``jaxsplit.spin_lattice`` (``--exchange``, ``--anisotropic``, ``--dm``, ``--anisotropy``,
``--axis``, ``--field``, ``--spin-length``), the initial state (``--initial``, ``--amplitude``,
``--seed``) and the integrator (``--method``: a split composed by ``--scheme``, or the
spherical midpoint or Heun). Shared with simulate: ``--scheme``, ``--dt``, ``--steps``,
``--t-end``, ``--save-every``, ``--dtype``, ``--out`` (.npz), ``--figure``, ``--no-figure``,
``--no-save``, ``--json``, ``--force``.

Outputs: the trajectory (npz: t, spins (K, *lattice shape, 3), energy, magnetisation, and the
metadata as JSON) and one figure: the final spin configuration, energy error and
magnetisation against time, and S(q, ω) (``jaxsplit.structure_factor``) along a path
through the Brillouin zone with the linear spin-wave curve where the model has one here
(a hypercubic ferromagnet along the field axis, or a Néel antiferromagnet).
"""

import json
import sys
import time
from pathlib import Path

import numpy as np

from ..core._errors import InputError
from . import _args, _io, _metadata

METHODS = ("bonds", "sublattice", "sweep", "spherical-midpoint", "heun")
DEFAULTS = {"lattice": "square", "size": "16", "exchange": 1.0, "anisotropic": 0.0, "anisotropy": 0.0,
            "axis": (0.0, 0.0, 1.0), "field": (0.0, 0.0, 0.0), "spin_length": 1.0, "amplitude": 0.05,
            "method": "bonds", "dt": 0.05, "steps": 2000}
OWN = {"lattice": "--lattice", "size": "--size", "open": "--open", "exchange": "--exchange",
       "anisotropic": "--anisotropic", "dm": "--dm", "anisotropy": "--anisotropy", "axis": "--axis",
       "field": "--field", "spin_length": "--spin-length", "initial": "--initial", "amplitude": "--amplitude",
       "method": "--method"}
THEIRS = {"inertia": "--inertia", "m0": "--m0", "split": "--split", "shift_axis": "--shift-axis", "tol": "--tol",
          "save_at": "--save-at", "renormalize": "--renormalize", "q0": "--q0", "center_of_mass": "--center-of-mass",
          "weight": "--weight", "rate": "--rate", "gamma0": "--gamma0", "noise": "--noise", "format": "--format"}
MAX_SAVED_BYTES = 2**30  # saved states beyond 1 GiB: raise --save-every
FREQUENCY_POINTS = 64  # at least this many saved states for S(q, ω)


def _finite(name):
    def parse(text):
        return _args.number(text, name)

    return parse


def add_arguments(parser, system_group) -> None:
    """Register --system spin-lattice and its options on simulate's parser."""
    action = next(a for a in parser._actions if a.dest == "system")
    action.choices = tuple(action.choices) + ("spin-lattice",)
    action.help += "; spin-lattice: classical spins on a lattice (jaxsplit.spin_lattice), state (N, 3)"
    from ..lattices import NAMES

    g = parser.add_argument_group("spin lattice (--system spin-lattice)")
    g.add_argument("--lattice", choices=NAMES, default=None, help=f"the lattice (default {DEFAULTS['lattice']})")
    g.add_argument("--size", default=None, metavar="LxM",
                   help="cells per axis: 64 (every axis) or 64x64 (default 16)")
    g.add_argument("--open", action="store_true", default=None, help="open boundaries (default periodic)")
    g.add_argument("--exchange", type=_finite("--exchange"), default=None, metavar="J",
                   help="J of -J S_i.S_j: > 0 ferromagnetic, < 0 antiferromagnetic (default 1)")
    g.add_argument("--anisotropic", type=_finite("--anisotropic"), default=None, metavar="DELTA",
                   help="XXZ: -DELTA S_i^z S_j^z per bond (default 0)")
    g.add_argument("--dm", type=_args.vector3("--dm", "Dx,Dy,Dz"), default=None, metavar="Dx,Dy,Dz",
                   help="Dzyaloshinskii-Moriya vector of D.(S_i x S_j) per bond (default none)")
    g.add_argument("--anisotropy", type=_finite("--anisotropy"), default=None, metavar="K",
                   help="uniaxial -K (n.S_i)^2 (default 0)")
    g.add_argument("--axis", type=_args.vector3("--axis", "x,y,z"), default=None, metavar="x,y,z",
                   help="anisotropy axis n (default 0,0,1)")
    g.add_argument("--field", type=_args.vector3("--field", "Bx,By,Bz"), default=None, metavar="Bx,By,Bz",
                   help="Zeeman -B.S_i (default 0,0,0)")
    g.add_argument("--spin-length", type=_args.positive_float, default=None, metavar="S", help="|S_i| (default 1)")
    g.add_argument("--initial", choices=("ferro", "neel", "random"), default=None,
                   help="initial state along the field (or z), perturbed by --amplitude (default: ferro for "
                        "exchange >= 0, neel for < 0)")
    g.add_argument("--amplitude", type=_args.nonnegative_float, default=None, metavar="A",
                   help="random tilt of each spin, radians, net moment removed (default 0.05)")
    g.add_argument("--method", choices=METHODS, default=None,
                   help="bonds (exact bond flows), sublattice, sweep (composed by --scheme), spherical-midpoint "
                        "or heun (default bonds)")


def refuse_stray(args) -> None:
    """One system's options given to another: refused, named."""
    if args.system == "spin-lattice":
        given = [flag for dest, flag in THEIRS.items() if getattr(args, dest, None) not in (None, False, 0.0)]
        if given:
            raise InputError(f"{', '.join(given)} do(es) not apply to --system spin-lattice")
    else:
        given = [flag for dest, flag in OWN.items() if getattr(args, dest, None) is not None]
        if given:
            raise InputError(f"{', '.join(given)} appl(ies) only to --system spin-lattice (this is --system "
                             f"{args.system})")


def _value(args, name):
    value = getattr(args, name, None)
    return DEFAULTS.get(name) if value is None else value


def build(args):
    """(system, x0 (N, 3) float64, parameters dict) from the arguments."""
    import jax.numpy as jnp

    import jaxsplit

    lat = jaxsplit.lattices.lattice(_value(args, "lattice"), _value(args, "size"), periodic=not args.open)
    parameters = {"lattice": lat.name, "size": list(lat.size), "periodic": lat.periodic, "n_sites": lat.n_sites,
                  **{k: _value(args, k) for k in ("exchange", "anisotropic", "anisotropy", "axis", "field",
                                                  "spin_length")},
                  "dm": None if args.dm is None else list(args.dm)}
    if not np.linalg.norm(parameters["axis"]) > 0:
        raise InputError("--axis must be a nonzero vector")
    system = jaxsplit.spin_lattice(lat, exchange=parameters["exchange"], anisotropic=parameters["anisotropic"],
                                   dm=args.dm, anisotropy=parameters["anisotropy"], axis=parameters["axis"],
                                   field=parameters["field"], spin_length=parameters["spin_length"])
    initial = args.initial or ("ferro" if parameters["exchange"] >= 0 else "neel")
    field = np.asarray(parameters["field"], float)
    direction = field if np.linalg.norm(field) > 0 else np.array([0.0, 0.0, 1.0])
    if initial == "random":
        x0 = system.random_state(args.seed)
    else:
        x0 = system.uniform(direction) if initial == "ferro" else system.neel(direction)
        x0 = system.perturbed(x0, _value(args, "amplitude"), seed=args.seed, zero_mean=True)
    parameters.update(initial=initial, amplitude=_value(args, "amplitude"), seed=args.seed)
    return system, jnp.asarray(x0, jnp.float64), parameters


def _step(system, method, scheme):
    import jaxsplit

    if method in ("spherical-midpoint", "heun"):
        if scheme is not None:
            raise InputError(f"--scheme composes splits; --method {method} is an integrator of its own")
        return (jaxsplit.spherical_midpoint if method == "spherical-midpoint" else jaxsplit.heun)(system), None
    scheme = scheme or "strang"
    return jaxsplit.splitting(system, scheme, method), scheme


def run(args) -> int:
    refuse_stray(args)
    with _io.Outputs(force=args.force) as outputs:
        return _run(args, outputs)


def _run(args, outputs) -> int:
    import jax
    import jax.numpy as jnp

    import jaxsplit

    system, x0, parameters = build(args)
    method = _value(args, "method")
    step, scheme = _step(system, method, args.scheme)
    dt = args.dt if args.dt is not None else DEFAULTS["dt"]
    if args.t_end is not None:
        n_steps = max(1, round(args.t_end / abs(dt)))
    else:
        n_steps = args.steps or DEFAULTS["steps"]
    save_every = args.save_every
    saved = n_steps // save_every + 2
    if saved * x0.size * 8 > MAX_SAVED_BYTES:
        raise InputError(f"{saved:,} saved states of {system.n_sites:,} spins need {saved * x0.size * 8 / 2**30:.1f} GiB "
                         f"(at most {MAX_SAVED_BYTES / 2**30:g}); raise --save-every")
    out = figure = None
    if args.no_save:
        if args.out or args.figure:
            raise InputError("--no-save contradicts --out/--figure")
    else:
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        out_path = Path(args.out) if args.out else Path("jaxsplit-runs") / f"simulate-{stamp}-spin-lattice.npz"
        if out_path.suffix.lower() not in (".npz", ""):
            raise InputError(f"--out {args.out!r}: a spin-lattice trajectory is written as .npz")
        out = outputs.file(out_path.with_suffix(".npz"), "trajectory")
        if not args.no_figure:
            figure = outputs.file(args.figure or out.with_suffix(".png"), "figure")
    dtype = jnp.float32 if args.dtype == "float32" else jnp.float64
    start = time.perf_counter()
    sol = jaxsplit.integrate(step, x0.astype(dtype), dt, n_steps, save_every=save_every)
    states = np.asarray(jax.block_until_ready(sol.x), dtype=np.float64)
    wall = time.perf_counter() - start
    t = np.asarray(sol.t, dtype=np.float64)
    if not np.all(np.isfinite(states)):
        raise InputError("the state became non-finite: lower --dt")
    energy = np.asarray(jax.vmap(system.hamiltonian)(jnp.asarray(states)))
    magnet = states.sum(axis=1)
    lengths = np.linalg.norm(states, axis=-1) / np.asarray(system.spin_length)
    summary = {"command": "simulate", "system": "spin-lattice", **parameters, "method": method, "scheme": scheme,
               "dt": dt, "steps": n_steps, "save_every": save_every, "dtype": args.dtype,
               "energy_max_relative_error": float(np.max(np.abs(energy - energy[0])) / max(abs(energy[0]), 1e-300)),
               "spin_length_max_relative_error": float(np.max(np.abs(lengths - 1))),
               "magnetisation_initial": magnet[0].tolist(), "magnetisation_final": magnet[-1].tolist(),
               "magnetisation_conserved": _conserved(system), "seconds": wall,
               "spin_steps_per_second": system.n_sites * n_steps / wall}
    if out is not None:
        meta = {**_metadata.run_metadata("simulate"), **summary}
        outputs.write_npz(out, {"t": t, "spins": states.reshape((len(t),) + system.lattice.shape + (3,)),
                                "energy": energy, "magnetisation": magnet,
                                "metadata": np.array(json.dumps(_metadata.jsonable(meta)))})
        summary["out"] = str(out)
    if figure is not None:
        from ._spin_figures import spin_figure

        outputs.write_bytes(figure, spin_figure(system, t, states, energy, magnet, parameters, summary))
        summary["figure"] = str(figure)
    if args.json:
        _metadata.print_json(summary)
    else:
        print(f"spin-lattice {parameters['lattice']} {'x'.join(map(str, parameters['size']))} ({system.n_sites:,} "
              f"spins), {method}{' ' + scheme if scheme else ''}, {n_steps:,} steps of {dt:g} in {wall:.2f} s "
              f"({summary['spin_steps_per_second']:.3g} spin-steps/s)")
        print(f"  energy error (relative) {summary['energy_max_relative_error']:.2e}, |S_i| error "
              f"{summary['spin_length_max_relative_error']:.1e}")
        for key in ("out", "figure"):
            if key in summary:
                print(f"  {key}: {summary[key]}", file=sys.stdout)
    return 0


def _conserved(system):
    axis = system.magnetisation_axis()
    return axis if isinstance(axis, str) or axis is None else [float(v) for v in axis]
