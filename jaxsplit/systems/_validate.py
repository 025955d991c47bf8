"""Validation of concrete system parameters and states: one-line ``InputError``s that name the
bad value and what is allowed. Traced values pass unchecked (shapes are checked while tracing
elsewhere), so the checks cost nothing inside jit, vmap and grad.
"""

import jax
import numpy as np

from ..core._errors import InputError
from ..core._state import host_values
from ._rigid_body import as_float_array, is_concrete
from .so3 import check_shape


def check_vector(value, name: str):
    """A finite (..., 3) array (checked when concrete)."""
    arr = as_float_array(value, name)
    if is_concrete(arr):
        if arr.ndim < 1 or arr.shape[-1] != 3:
            raise InputError(f"{name} must have 3 components, got shape {tuple(arr.shape)}")
        values = host_values(arr)
        if not np.all(np.isfinite(values)):
            raise InputError(f"{name} must be finite, got {values.tolist()}")
    return arr


def check_non_negative(value, name: str):
    """A finite number (or batch) >= 0 (checked when concrete)."""
    arr = as_float_array(value, name)
    if is_concrete(arr):
        values = host_values(arr)
        if not np.all(np.isfinite(values)) or not np.all(values >= 0):
            raise InputError(f"{name} must be finite and >= 0, got {values.tolist()}")
    return arr


def check_batches(**batches):
    """The parameters' batch shapes (name -> shape) broadcast together (static: checked under jit)."""
    try:
        return np.broadcast_shapes(*batches.values())
    except ValueError:
        shown = ", ".join(f"{name} {tuple(shape)}" for name, shape in batches.items())
        raise InputError(f"the parameters' batch shapes do not broadcast together: {shown}") from None


def _show(values) -> str:
    """A short one-line rendering of concrete values (a batch by its count and worst entry)."""
    values = np.asarray(values)
    if values.size <= 9:
        return str(np.round(values, 12).tolist())
    return f"{values.size} values incl. {np.round(values.reshape(-1)[0], 12)}"


def check_finite_state(x, label: str):
    """Every leaf of a concrete state finite."""
    for k, leaf in enumerate(jax.tree_util.tree_leaves(x)):
        values = host_values(leaf)
        if values is not None and not np.all(np.isfinite(values)):
            bad = values[~np.isfinite(values)]
            raise InputError(f"{label} must be finite, got {_show(bad)} in part {k}")


_EYE = np.eye(3)
_TOLERANCE: dict = {}  # √ε per dtype (finfo costs microseconds, and integrate checks every call)


def check_unit(values, what: str, name: str, dtype):
    """``values`` (norms, or deviations + 1) equal to 1 to √ε of ``dtype``."""
    tol = _TOLERANCE.get(np.dtype(dtype)) or _TOLERANCE.setdefault(np.dtype(dtype), float(np.sqrt(np.finfo(dtype).eps)))
    values = np.asarray(values, dtype=float)
    off = ~(np.abs(values - 1) <= tol)  # NaN is off too
    if off.any():
        raise InputError(f"{what} ({name} = 1 to {tol:.1e}), got {name} = {_show(values[off])}")


def _values(leaf):
    """A concrete floating leaf as a NumPy array (None when traced or not floating)."""
    if not is_concrete(leaf) or not np.issubdtype(leaf.dtype if hasattr(leaf, "dtype") else np.result_type(leaf), np.floating):
        return None
    return host_values(leaf)


def check_attitude(a, quaternion: bool):
    """A concrete attitude: Q ∈ SO(3) (QᵀQ = 1 and det Q = 1) or a unit quaternion q, to √ε of
    its dtype (QᵀQ and |q| are Casimirs: a state from a long run passes; NaN fails). A rotation
    flow keeps whatever it is given, so anything else would integrate to a meaningless attitude.
    Plain NumPy on the concrete values: ``integrate`` runs it on every call."""
    a = _values(a)
    if a is None:
        return
    if quaternion:
        check_unit(np.sqrt(np.einsum("...i,...i->...", a, a)), "q must be a unit quaternion", "|q|", a.dtype)
        return
    gram = np.einsum("...ki,...kj->...ij", a, a)
    check_unit(1 + np.abs(gram - _EYE).max(axis=(-1, -2)), "Q must be orthogonal (and finite)",
               "1 + max|QᵀQ − 1|", a.dtype)
    r0, r1, r2 = a[..., 0, :], a[..., 1, :], a[..., 2, :]  # det by rows (np.cross costs 0.2 ms a call)
    det = (r0[..., 0] * (r1[..., 1] * r2[..., 2] - r1[..., 2] * r2[..., 1])
           - r0[..., 1] * (r1[..., 0] * r2[..., 2] - r1[..., 2] * r2[..., 0])
           + r0[..., 2] * (r1[..., 0] * r2[..., 1] - r1[..., 1] * r2[..., 0]))
    check_unit(det, "Q must be a rotation, not a reflection", "det Q", a.dtype)


def check_parts(state, parts):
    """The concrete values of the parts a rotation flow declares (``so3``): an ``"attitude"``
    part must be a rotation matrix, a ``"quaternion"`` part a unit quaternion; momenta and
    body vectors may be any finite vector."""
    if parts is None or not isinstance(state, tuple) or len(state) != len(parts):
        return state  # the flow's own shape check names a wrong layout
    for part, leaf in zip(parts, state):
        if part in ("attitude", "quaternion"):
            check_shape(leaf, part)  # the shape first: its message names the layout
            check_attitude(leaf, part == "quaternion")
    return state
