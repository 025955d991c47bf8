"""Batches of cases for the exploration tools: one family of systems, many (state, parameters).

A *family* is a callable ``params -> system`` (``RigidBody`` itself is one: inertia ->
body). Cases are PyTrees with a leading case axis N: ``x0`` (states) and ``params``. The
family is called on traced per-case parameters inside ``vmap``, and once on the concrete
batch to validate it (so a family accepts a leading batch axis when concrete).

Split options whose value is ``"auto"`` depend on concrete parameters (the rigid body's
Casimir shift axis): ``resolved_groups`` resolves them per case and groups the cases by the
result, so each group compiles once with explicit options.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from ..core._errors import InputError
from ..core._state import as_state, float_dtype, leading_size, ravel
from ..systems._base import AbstractSystem
from ..systems._rigid_body import RigidBody, flag

STATE_KEYS = ("x0", "m0")
PARAM_KEYS = ("params", "inertia")


def any_body(inertia):
    """The default family when non-physical bodies are wanted (module-level: a stable key)."""
    return RigidBody(inertia, allow_nonphysical=True)


def family_of(system, allow_nonphysical: bool = False):
    """A callable params -> system (the rigid-body class by default, whose concrete bodies
    ``allow_nonphysical`` admits as ``RigidBody`` does; a family of your own decides itself)."""
    if system is None:
        return any_body if flag(allow_nonphysical) else RigidBody
    if isinstance(system, AbstractSystem):
        raise InputError("pass a family params -> system (e.g. jaxsplit.RigidBody, or a function building "
                         "your system from per-case parameters), not one system instance")
    if not callable(system):
        raise InputError(f"system must be a callable params -> system, got {system!r}")
    return system


def build(family, params):
    system = family(params)
    if not isinstance(system, AbstractSystem):
        raise InputError(f"the family must return a system (AbstractSystem), got {type(system).__name__}")
    return system


def case_arrays(cases) -> tuple:
    """(states key, x0, params, h) from a cases dict; every leaf with the leading axis N."""
    if not isinstance(cases, dict):
        raise InputError(f"cases must be a dict with a state ({' or '.join(STATE_KEYS)}), parameters "
                         f"({' or '.join(PARAM_KEYS)}) and h (see sweep_cases)")
    state_key = next((k for k in STATE_KEYS if k in cases), None)
    param_key = next((k for k in PARAM_KEYS if k in cases), None)
    if state_key is None or param_key is None or "h" not in cases:
        raise InputError(f"cases must be a dict with keys {STATE_KEYS[0]!r} (or {STATE_KEYS[1]!r}), "
                         f"{PARAM_KEYS[0]!r} (or {PARAM_KEYS[1]!r}) and 'h' (see sweep_cases); got {sorted(cases)}")
    x0 = jax.tree_util.tree_map(np.asarray, as_state(cases[state_key], f"cases[{state_key!r}]"))
    params = jax.tree_util.tree_map(np.asarray, cases[param_key])
    h = np.asarray(cases["h"])
    if not all(np.issubdtype(a.dtype, np.number) and not np.iscomplexobj(a)
               for a in jax.tree_util.tree_leaves((params, h))):
        raise InputError(f"cases[{param_key!r}] and cases['h'] must be real numbers")
    n = leading_size(x0, f"cases[{state_key!r}]")
    if leading_size(params, f"cases[{param_key!r}]") != n or h.shape != (n,) or n == 0:
        raise InputError(f"cases need {state_key}, {param_key} and h with one leading axis N >= 1; got "
                         f"{_shapes(cases[state_key])}, {_shapes(cases[param_key])}, {h.shape}")
    dtype = np.dtype(float_dtype(x0))  # the computation follows the states' dtype
    for name, tree in ((state_key, x0), (param_key, params), ("h", h)):
        if not all(np.all(np.isfinite(a)) for a in jax.tree_util.tree_leaves(tree)):
            raise InputError(f"cases[{name!r}] must be finite")
    if np.any(h <= 0):
        raise InputError("cases['h'] must be positive step sizes")
    zero = np.all(ravel_rows(x0) == 0, axis=1)
    if np.any(zero):
        raise InputError(f"cases[{state_key!r}] must be non-zero (case {int(np.argmax(zero))} is zero)")
    params = jax.tree_util.tree_map(lambda a: a.astype(dtype), params)
    return state_key, x0, params, h.astype(dtype)


def _shapes(tree):
    return jax.tree_util.tree_map(np.shape, tree)


def ravel_rows(tree) -> np.ndarray:
    """(N, D): every case's leaves flattened side by side."""
    leaves = jax.tree_util.tree_leaves(tree)
    n = len(leaves[0])
    return np.concatenate([np.asarray(a).reshape(n, -1) for a in leaves], axis=1)


def take(tree, idx):
    return jax.tree_util.tree_map(lambda a: a[idx], tree)


def resolved_groups(family, params, split, options: dict) -> list[tuple[str, dict, np.ndarray]]:
    """[(split name, explicit options, case indices)]: options equal to "auto" resolved per case."""
    n = leading_size(params, "params")
    auto = [k for k, v in options.items() if isinstance(v, str) and v == "auto"]
    if not auto:
        name, opts = build(family, take(params, 0)).resolve_split(split, **options)
        return [(name, opts, np.arange(n))]
    groups: dict = {}
    for i in range(n):
        name, opts = build(family, take(params, i)).resolve_split(split, **options)
        key = (name, tuple(sorted(opts.items())))
        groups.setdefault(key, []).append(i)
    return [(name, dict(opts), np.asarray(idx)) for (name, opts), idx in groups.items()]


def resolve_devices(devices):
    if devices is None:
        devices = jax.devices()
    devices = list(devices)
    if not devices:
        raise InputError("devices must hold at least one JAX device")
    return devices


_COMPILED: dict = {}


def compiled(key, build_kernel, devices):
    """jit(kernel) on one device, or jit(shard_map(kernel)) over a 1-D mesh of ``devices``."""
    full_key = (key, tuple(devices) if devices is not None else None)
    if full_key not in _COMPILED:
        fn = build_kernel()
        if devices is not None and len(devices) > 1:
            mesh = Mesh(np.asarray(devices), ("cases",))
            fn = jax.shard_map(fn, mesh=mesh, in_specs=P("cases"), out_specs=P("cases"))
        _COMPILED[full_key] = jax.jit(fn)
    return _COMPILED[full_key]


def chunked(fn, arrays: list, chunk_size: int, multiple: int):
    """Apply ``fn`` to equal-size chunks of ``arrays`` (PyTrees with a leading axis, padded
    with the last case) and concatenate the results."""
    n = leading_size(arrays, "the batch")
    size = max(multiple, math.ceil(min(chunk_size, n) / multiple) * multiple)
    outs = []
    for start in range(0, n, size):
        piece = take(arrays, slice(start, start + size))
        pad = size - min(size, n - start)
        if pad:
            piece = jax.tree_util.tree_map(lambda a, pad=pad: np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]), piece)
        res = fn(*piece)
        outs.append(jax.tree_util.tree_map(lambda r, pad=pad: np.asarray(r)[: size - pad], res))
    return jax.tree_util.tree_map(lambda *parts: np.concatenate(parts), *outs)


def relative_change(value, initial):
    """max|I − I0| / max|I0| (the absolute change where I0 = 0); vector invariants in the max norm."""
    diff = jnp.max(jnp.abs(jnp.ravel(value - initial)))
    scale = jnp.max(jnp.abs(jnp.ravel(initial)))
    return jnp.where(scale > 0, diff / jnp.where(scale > 0, scale, 1), diff)


def state_distance(a, b):
    """Max-norm distance between two states (floating leaves)."""
    return jnp.max(jnp.abs(ravel(a)[0] - ravel(b)[0]))


def max_rate(system, flows, x0):
    """An estimate of the fastest frequency of the pieces: the system's own bound
    (``max_rate``) where it declares one, else the largest spectral norm of the Jacobian of a
    piece's generator x -> ∂_t φ_k(x, 0) at x0 (|c m_k| for a rotation by c m_k t)."""
    if hasattr(system, "max_rate"):
        return system.max_rate(x0)
    flat, unravel = ravel(x0)
    one = jnp.ones((), flat.dtype)
    norms = []
    for f in flows:
        def generator(v, f=f):
            return ravel(jax.jvp(lambda t: f(unravel(v), t), (0 * one,), (one,))[1])[0]

        norms.append(jnp.linalg.norm(jax.jacfwd(generator)(flat), 2))
    return jnp.max(jnp.stack(norms))
