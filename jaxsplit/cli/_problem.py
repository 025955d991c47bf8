"""The problem the commands share: the system, its initial state, the scheme and the split.

``SYSTEMS`` is what the command line integrates: the free rigid body (state m), the free
body with its attitude (m, Q), the heavy top and the gravity-gradient satellite (m, Γ).
``add_system_arguments`` declares their options once for every command, ``problem(args)``
checks them and builds a ``Problem``, and ``scheme_and_split`` picks the split a scheme can
compose. Each refusal names the option at fault: a moment whose inverse overflows float64
is the inertia's, an energy that overflows is the state's, a Γ0 off the unit sphere or an
option of another system is refused rather than normalised or ignored. The CLI labels axes
1, 2, 3 like I1, I2, I3; the library counts from 0.
"""

import inspect
import math
from typing import Any, NamedTuple

import numpy as np

from ..core._errors import InputError
from ..systems._rigid_body import PAPER_BODY, PAPER_M0
from . import _args, _bounds

UNIT_TOL = 1e-9  # |Γ0| and |q0| must be 1 to this relative tolerance (a typed 0.6,0,0.8 is exact enough)


class Spec(NamedTuple):
    """How the command line builds one system: its state's parts and the options it takes."""

    parts: tuple  # ("m",), ("m", "Q") or ("m", "gamma")
    options: tuple  # the system's own options (beyond --inertia, --m0)
    defaults: dict  # default values of --m0 and of its own options
    exact: bool  # the free body's elliptic solution applies
    what: str


SYSTEMS = {
    "rigid-body": Spec(("m",), (), {"m0": PAPER_M0}, True, "free rigid body, state m"),
    "attitude": Spec(("m", "Q"), ("q0",), {"m0": PAPER_M0, "q0": (1.0, 0.0, 0.0, 0.0)}, True,
                     "free rigid body with its attitude Q (body to space), state (m, Q)"),
    "heavy-top": Spec(("m", "gamma"), ("center_of_mass", "weight", "gamma0"),
                      {"m0": (0.0, 0.4, 3.0), "center_of_mass": (0.0, 0.0, 0.5), "weight": 1.0,
                       "gamma0": (0.0, 0.6, 0.8)}, False,
                      "heavy top, state (m, Gamma), Gamma the upward vertical in the body"),
    "gravity-gradient": Spec(("m", "gamma"), ("rate", "gamma0"),
                             {"m0": PAPER_M0, "rate": 1.0, "gamma0": (0.0, 0.6, 0.8)}, False,
                             "satellite in a gravity gradient, state (m, Gamma), Gamma towards the planet"),
}
OPTION_NAMES = {"q0": "--q0", "center_of_mass": "--center-of-mass", "weight": "--weight", "rate": "--rate",
                "gamma0": "--gamma0"}
PART_LABELS = {"m": "m", "Q": "Q", "gamma": "Gamma"}


class Problem(NamedTuple):
    """A checked system and initial state (NumPy float64 parts), with what the commands report."""

    name: str  # the CLI name of the system
    system: Any
    x0: Any  # m0 (3,), or a tuple (m0, Q0) / (m0, Gamma0)
    parts: tuple
    parameters: dict  # every parameter, for summaries and metadata
    exact: bool  # the elliptic solution applies

    @property
    def norms(self):
        """The norms a projection (``--renormalize``) restores: |m| of a free body, the unit rows
        of Q, |Γ| (|m| is no invariant of a body in a potential)."""
        if self.name == "rigid-body":
            return np.linalg.norm(self.x0)
        if self.name == "attitude":
            return (np.linalg.norm(self.x0[0]), np.ones(3))
        return (None, np.linalg.norm(self.x0[1]))

    def state(self, dtype=np.float64):
        """x0 in ``dtype`` as JAX arrays."""
        import jax.numpy as jnp

        if isinstance(self.x0, tuple):
            return tuple(jnp.asarray(p, dtype=dtype) for p in self.x0)
        return jnp.asarray(self.x0, dtype=dtype)


def fmt_vec(v) -> str:
    return ",".join(f"{float(x):g}" for x in np.ravel(v))


def fmt_value(v) -> str:
    """A parameter as the CLI writes it: a number, or a vector in parentheses."""
    return f"{float(v):g}" if np.ndim(v) == 0 else f"({fmt_vec(v)})"


def add_system_arguments(group, *, systems=tuple(SYSTEMS), state_help="initial body angular momentum"):
    """--system and every system's options (defaults None: each system has its own)."""
    group.add_argument("--system", choices=systems, default="rigid-body",
                       help="what to integrate (default rigid-body): " + "; ".join(
                           f"{name}: {SYSTEMS[name].what}" for name in systems))
    group.add_argument("--inertia", type=_args.vector3("--inertia", "I1,I2,I3"), default=None, metavar="I1,I2,I3",
                       help=f"principal moments of inertia, all > 0 (default {fmt_vec(PAPER_BODY)})")
    group.add_argument("--m0", type=_args.vector3("--m0"), default=None, metavar="A,B,C",
                       help=f"{state_help} (default {fmt_vec(PAPER_M0)}; heavy-top "
                            f"{fmt_vec(SYSTEMS['heavy-top'].defaults['m0'])})")
    group.add_argument("--allow-nonphysical", action="store_true",
                       help="accept a body that violates the triangle inequalities I1 + I2 >= I3 (etc.)")
    if "attitude" in systems:
        group.add_argument("--q0", type=_args.vector("--q0", 4, "w,x,y,z"), default=None, metavar="W,X,Y,Z",
                           help="attitude: initial attitude as a unit quaternion (default 1,0,0,0: body axes = space axes)")
    if "heavy-top" in systems:
        group.add_argument("--center-of-mass", type=_args.vector3("--center-of-mass", "X,Y,Z"), default=None,
                           metavar="X,Y,Z", help="heavy-top: centre of mass from the fixed point, body frame "
                                                 f"(default {fmt_vec(SYSTEMS['heavy-top'].defaults['center_of_mass'])})")
        group.add_argument("--weight", type=_args.nonnegative_float, default=None, metavar="W",
                           help="heavy-top: weight M g >= 0 (0: a free body carrying the vertical; default 1)")
    if "gravity-gradient" in systems:
        group.add_argument("--rate", type=_args.nonnegative_float, default=None, metavar="OMEGA",
                           help="gravity-gradient: orbital rate >= 0 (default 1)")
    if "heavy-top" in systems or "gravity-gradient" in systems:
        group.add_argument("--gamma0", type=_args.vector3("--gamma0"), default=None, metavar="A,B,C",
                           help="heavy-top, gravity-gradient: initial Gamma, a unit vector (default "
                                f"{fmt_vec(SYSTEMS['heavy-top'].defaults['gamma0'])})")


def add_split_arguments(group, default_help="the first split of the system that the scheme can compose"):
    group.add_argument("--split", choices=("axes", "casimir", "spin", "symmetric"), default=None,
                       help="rigid-body: axes (three rotations, the paper) or casimir (two, shifted by C/I_k); "
                            "attitude: axes or spin (two); heavy-top, gravity-gradient: axes (three rotations and "
                            f"the kick) or symmetric (two, I1 = I2) (default: {default_help})")
    group.add_argument("--shift-axis", choices=("auto", "1", "2", "3"), default=None,
                       help="axis k of the shift, with --split casimir or spin (default auto: the middle 1/I)")


# --------------------------------------------------------------------------- the problem


def problem(args) -> Problem:
    """The checked system and initial state of ``args`` (see the module docstring)."""
    name = getattr(args, "system", "rigid-body")
    spec = SYSTEMS[name]
    for option, flag in OPTION_NAMES.items():
        if getattr(args, option, None) is not None and option not in spec.options:
            users = [n for n, s in SYSTEMS.items() if option in s.options]
            raise InputError(f"{flag} applies only to --system {' or '.join(users)} (this is --system {name})")
    inertia = tuple(args.inertia) if args.inertia is not None else PAPER_BODY
    rigid = body(inertia, args.allow_nonphysical)
    value = {k: getattr(args, k, None) for k in spec.options}
    value = {k: spec.defaults[k] if v is None else v for k, v in value.items()}
    m0 = np.asarray(args.m0 if args.m0 is not None else spec.defaults["m0"], dtype=np.float64)
    parameters = {"system": name, "inertia": list(inertia)}
    import jax.numpy as jnp

    from ..systems._attitude import attitude
    from ..systems._gravity_gradient import gravity_gradient
    from ..systems._heavy_top import heavy_top
    from ..systems.so3 import quaternion_to_matrix

    if name == "rigid-body":
        system, x0 = rigid, initial_state(m0, inertia)
    elif name == "attitude":
        q0 = unit_vector(value["q0"], "--q0", "a unit quaternion w,x,y,z (the identity is 1,0,0,0)")
        system = attitude(rigid.inertia, allow_nonphysical=True)  # checked by body()
        x0 = (initial_state(m0, inertia), np.asarray(quaternion_to_matrix(jnp.asarray(q0))))
        parameters |= {"q0": list(value["q0"])}
    else:
        gamma0 = unit_vector(value["gamma0"], "--gamma0", "a unit vector (a direction)")
        if name == "heavy-top":
            system = heavy_top(rigid.inertia, jnp.asarray(value["center_of_mass"], dtype=jnp.float64),
                               jnp.asarray(value["weight"], dtype=jnp.float64), allow_nonphysical=True)
            parameters |= {"center_of_mass": list(value["center_of_mass"]), "weight": value["weight"]}
        else:
            system = gravity_gradient(rigid.inertia, jnp.asarray(value["rate"], dtype=jnp.float64),
                                      allow_nonphysical=True)
            parameters |= {"rate": value["rate"]}
        x0 = (initial_state(m0, inertia, kinetic_only=True), gamma0)
        parameters |= {"gamma0": list(value["gamma0"])}
        _finite_energy(system, x0, name)
    parameters["m0"] = m0.tolist()
    return Problem(name, system, x0, spec.parts, parameters, spec.exact)


def body(inertia, allow_nonphysical: bool):
    """A RigidBody from a parsed --inertia: the library's check of the moments (positive,
    1/I representable, physical unless --allow-nonphysical), naming the options."""
    import jax.numpy as jnp

    from ..systems._rigid_body import RigidBody, check_moments

    check_moments(np.asarray(inertia, dtype=np.float64), "--inertia", allow_nonphysical, "--allow-nonphysical")
    return RigidBody(jnp.asarray(inertia, dtype=jnp.float64), allow_nonphysical=True)  # checked above


def initial_state(m0, inertia, kinetic_only: bool = False) -> np.ndarray:
    """--m0 as float64, refused when |m0|^2 or the energy overflows (naming who is at fault)."""
    m0 = np.asarray(m0, dtype=np.float64)
    with np.errstate(over="ignore"):
        casimir = 0.5 * np.sum(m0 * m0)
        energy = 0.5 * np.sum(m0 * m0 / np.asarray(inertia, dtype=np.float64))
    if not np.isfinite(casimir):
        raise InputError(f"--m0 {fmt_vec(m0)} is too large: |m0|^2 overflows float64")
    if not np.isfinite(energy):
        what = "kinetic energy" if kinetic_only else "energy"
        raise InputError(f"--m0 {fmt_vec(m0)} with --inertia {fmt_vec(inertia)}: the {what} sum m_i^2/(2 I_i) "
                         "overflows float64")
    return m0


def unit_vector(values, option: str, what: str) -> np.ndarray:
    """``values`` when its norm is 1 (to ``UNIT_TOL``); refused otherwise, never normalised silently."""
    v = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore"):
        norm = float(np.linalg.norm(v))
    if not abs(norm - 1) <= UNIT_TOL:
        hint = (f"; e.g. {option} " + ",".join(f"{x:.17g}" for x in v / norm)) if 0 < norm < math.inf else ""
        raise InputError(f"{option} {fmt_vec(v)} has norm {norm:.9g}; it must be {what}, norm 1{hint}")
    return v


def _finite_energy(system, x0, name):
    import jax.numpy as jnp

    energy = float(system.hamiltonian(tuple(jnp.asarray(p) for p in x0)))
    if not math.isfinite(energy):
        raise InputError(f"--system {name}: the energy at the initial state overflows float64 (--m0, --inertia and "
                         "the potential's parameters are too large together)")


# --------------------------------------------------------------------------- scheme and split


class Method(NamedTuple):
    """A scheme and the split it composes, with the library's options (the shift 0-based)."""

    scheme: Any
    split: str
    options: dict
    chosen: bool  # the scheme does not fit the system's default split: another was chosen

    @property
    def shift_label(self):
        """The shift axis as the CLI labels it (1, 2, 3), or None."""
        return None if "shift" not in self.options else self.options["shift"] + 1


def _pieces(system, split, options):
    return len(system.split(split, **options))


def scheme_and_split(args, prob: Problem, option: str = "--scheme") -> Method:
    """The scheme named by ``option`` (bounded in stages) and the split: ``--split``, else the
    system's first split with as many pieces as the scheme composes. A stray ``--shift-axis``
    and a split the system does not offer (with the library's reason) are refused."""
    scheme = _bounds.scheme(getattr(args, option.lstrip("-").replace("-", "_")), option)
    system = prob.system
    offered = system.splits()
    requested = getattr(args, "split", None)
    shift = getattr(args, "shift_axis", None)
    if requested is not None and requested not in offered:
        why = system.refused_splits.get(requested)
        raise InputError(f"--split {requested} is not offered by --system {prob.name}" + (f" ({why})" if why else "")
                         + f"; offered: {', '.join(offered)}")
    shifted = [s for s in offered if "shift" in inspect.signature(offered[s]).parameters]
    if requested is not None:
        candidates = [requested]
    else:  # a --shift-axis asks for a shifted split
        candidates = shifted if shift is not None and shifted else list(offered)
    fits, problems = [], []
    for split in candidates:
        takes_shift = split in shifted
        options = {"shift": "auto" if shift in (None, "auto") else int(shift) - 1} if takes_shift else {}
        try:
            name, options = system.resolve_split(split, **options)
            pieces = _pieces(system, name, options)
        except InputError as err:  # e.g. the heavy top's symmetric split on an asymmetric body
            if requested is not None:
                raise InputError(f"--split {requested}: {err}") from None
            problems.append(f"{split}: {err}")
            continue
        if scheme.pieces_allowed(pieces):
            fits.append((name, options, takes_shift))
            break
        problems.append(f"{split}: {pieces} pieces")
    if not fits:
        other = [s for s in offered if s != requested]
        hint = f"; use --split {' or '.join(other)}" if requested is not None and other else ""
        raise InputError(f"{option} {scheme.name} is {scheme.form} (exactly two pieces) and does not fit "
                         + (f"--split {requested} ({problems[0].split(': ', 1)[1]})" if requested is not None else
                            f"any split of --system {prob.name} ({'; '.join(problems)})") + hint)
    name, options, takes_shift = fits[0]
    if shift is not None and not takes_shift:
        raise InputError(f"--shift-axis applies only with a shifted split (--split casimir of rigid-body, spin of "
                         f"attitude), not --split {name}")
    return Method(scheme, name, options, requested is None and name != system.default_split)
