"""The rigid-body problem the commands share: the body, the initial state, the scheme and split.

Each check names the option at fault: a moment whose inverse overflows float64 is the
inertia's fault, an energy that overflows is the pair's. The CLI labels the Casimir shift
axis 1, 2, 3 like I1, I2, I3; the library counts axes from 0.
"""

import numpy as np

from ..core._errors import InputError
from . import _bounds


def fmt_vec(v) -> str:
    return ",".join(f"{float(x):g}" for x in v)


def body(inertia, allow_nonphysical: bool):
    """A RigidBody from a parsed --inertia, refusing non-physical bodies unless allowed."""
    import jax.numpy as jnp

    from ..systems._rigid_body import RigidBody

    if not all(v > 0 for v in inertia):
        raise InputError(f"--inertia must be positive (I1,I2,I3 > 0), got {fmt_vec(inertia)}")
    with np.errstate(over="ignore", divide="ignore"):
        inverse = 1 / np.asarray(inertia, dtype=np.float64)
    if not np.all(np.isfinite(inverse)):
        k = int(np.argmin(np.isfinite(inverse)))
        raise InputError(f"--inertia {fmt_vec(inertia)}: 1/I{k + 1} overflows float64 (each moment must be at least "
                         f"{1 / np.finfo(np.float64).max:.2g})")
    rigid = RigidBody(jnp.asarray(inertia, dtype=jnp.float64))
    if not allow_nonphysical and not rigid.is_physical():
        i = inertia
        for a, b, c, names in ((0, 1, 2, "I1 + I2 >= I3"), (1, 2, 0, "I2 + I3 >= I1"), (2, 0, 1, "I3 + I1 >= I2")):
            if i[a] + i[b] < i[c]:
                failed = f"{names} fails ({i[a]:g} + {i[b]:g} < {i[c]:g})"
                break
        raise InputError(
            f"--inertia {fmt_vec(inertia)} is not a physical body: triangle inequality {failed}; "
            "pass --allow-nonphysical to integrate it anyway"
        )
    return rigid


def initial_state(m0, inertia) -> np.ndarray:
    """--m0 as float64, refused when |m0|^2 or the energy overflows (naming who is at fault)."""
    m0 = np.asarray(m0, dtype=np.float64)
    with np.errstate(over="ignore"):
        casimir = 0.5 * np.sum(m0 * m0)
        energy = 0.5 * np.sum(m0 * m0 / np.asarray(inertia, dtype=np.float64))
    if not np.isfinite(casimir):
        raise InputError(f"--m0 {fmt_vec(m0)} is too large: |m0|^2 overflows float64")
    if not np.isfinite(energy):
        raise InputError(f"--m0 {fmt_vec(m0)} with --inertia {fmt_vec(inertia)}: the energy sum m_i^2/(2 I_i) "
                         "overflows float64")
    return m0


def scheme_and_shift(args, rigid):
    """The scheme named by ``--scheme`` (bounded in stages) and the Casimir shift axis as the
    CLI labels it (``None`` for the axes split), refusing a scheme that does not fit
    ``--split`` and a stray ``--shift-axis``."""
    scheme = _bounds.scheme(args.scheme)
    if not scheme.pieces_allowed(3 if args.split == "axes" else 2):
        raise InputError(f"--scheme {scheme.name} is {scheme.form} (exactly two pieces) and does not fit "
                         "--split axes (three pieces); use --split casimir")
    if args.shift_axis is not None and args.split != "casimir":
        raise InputError("--shift-axis applies only with --split casimir")
    shift = "auto" if args.shift_axis in (None, "auto") else int(args.shift_axis)
    if args.split == "casimir" and shift == "auto":
        shift = rigid.shift_axis("auto") + 1
    return scheme, shift


def split_options(split: str, shift) -> dict:
    """The library's split options from the CLI's 1-based ``--shift-axis`` label."""
    return {"shift": int(shift) - 1} if split == "casimir" else {}
