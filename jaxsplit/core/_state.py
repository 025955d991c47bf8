"""States are any PyTree: the floating leaves evolve, integer leaves ride along untouched.

``host_values`` is the one way the library looks at a state's or a parameter's values on the
host (validation, choices that shape the compiled program): it also reads a global array
spread over several processes (``jax.distributed``), where ``np.asarray`` would refuse.

``float_dtype`` is the dtype a computation on a state follows (the step size is cast to
it, never the state to the step size). ``ravel`` flattens the floating leaves into one
vector, the coordinates in which the structure checks take Jacobians and a system's
Poisson matrix is written, and rebuilds the state around the untouched integer leaves.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._errors import InputError


def is_floating(leaf) -> bool:
    return jnp.issubdtype(jnp.result_type(leaf), jnp.floating)


def float_dtype(state):
    """The common dtype of the floating leaves (the default float when there are none)."""
    leaves = [leaf for leaf in jax.tree_util.tree_leaves(state) if is_floating(leaf)]
    return jnp.result_type(*leaves) if leaves else jnp.result_type(float)


def host_values(x, whole: bool = False, where: bool = False):
    """The values of ``x`` this process may look at, as NumPy; ``None`` when ``x`` is traced.

    An ordinary array (or one replicated on every device) is read whole. A global array
    spread over several processes gives what this process holds: its addressable shards
    assembled into the block of the global array they cover, so checks of entries (finite,
    positive, of unit length) run in each process on its own part, with no communication.
    ``whole=True`` gathers the whole array from every process instead: a collective, which
    every process must reach (they all run the same program); for values that decide the
    compiled program (which terms exist, a split's pieces), which must be the same everywhere.
    ``where=True`` also returns the block's slices into the global array (``...`` when whole).
    """
    if isinstance(x, jax.core.Tracer):
        return (None, None) if where else None
    if not isinstance(x, jax.Array) or x.is_fully_addressable or x.is_fully_replicated:
        values = np.asarray(x)
        return (values, ...) if where else values
    box = None if whole else _addressable_block(x)
    if box is None:  # gathered (asked for, or the shards held here do not tile one block)
        from jax.experimental import multihost_utils

        values = np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return (values, ...) if where else values
    return box if where else box[0]


def _addressable_block(x):
    """(values, slices) of the block of ``x`` its addressable shards tile; None if they do not."""
    blocks = {}
    for shard in x.addressable_shards:
        bounds = tuple(index.indices(n)[:2] for index, n in zip(shard.index, x.shape))
        blocks.setdefault(bounds, shard.data)  # replicas of one block: read once
    low = [min(b[a][0] for b in blocks) for a in range(x.ndim)]
    high = [max(b[a][1] for b in blocks) for a in range(x.ndim)]
    shape = tuple(h - lo for lo, h in zip(low, high))
    if sum(int(np.prod([h - lo for lo, h in b])) for b in blocks) != int(np.prod(shape)):
        return None
    values = np.empty(shape, x.dtype)
    for bounds, data in blocks.items():
        values[tuple(slice(lo - o, h - o) for (lo, h), o in zip(bounds, low))] = np.asarray(data)
    return values, tuple(slice(lo, h) for lo, h in zip(low, high))


def as_state(x0, name: str = "x0"):
    """Leaves as arrays. A state whose leaves are all integers (``m0 = [1, 0, 0]``) is
    promoted to the default float dtype; in a state with floating leaves, integer leaves
    stay integers, and floating leaves of different precisions are promoted to the widest
    (a step mixes them anyway, and a loop carries one dtype per leaf: never cast down).
    Complex, boolean, empty and non-numeric states are refused."""
    if isinstance(x0, jax.Array) and jnp.issubdtype(x0.dtype, jnp.floating):
        return x0  # the common case, cheaply
    leaves, treedef = jax.tree_util.tree_flatten(x0)
    if not leaves:
        raise InputError(f"{name} must hold at least one array, got {x0!r}")
    arrays = []
    for leaf in leaves:
        try:
            arr = jnp.asarray(leaf)
        except (TypeError, ValueError) as err:
            raise InputError(f"{name} must be numeric arrays, got {_describe(leaf)}") from err
        if jnp.issubdtype(arr.dtype, jnp.complexfloating):
            raise InputError(f"{name} must be real, got dtype {arr.dtype}")
        if not (jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer)):
            raise InputError(f"{name} must be real numbers, got dtype {arr.dtype}")
        arrays.append(arr)
    floating = [a for a in arrays if is_floating(a)]
    common = jnp.result_type(*floating) if floating else jnp.result_type(float)  # arrays: weak types respected
    promote = is_floating if floating else (lambda a: True)  # no floating leaf: all become floats
    arrays = [a.astype(common) if promote(a) and a.dtype != common else a for a in arrays]
    return jax.tree_util.tree_unflatten(treedef, arrays)


def _describe(leaf) -> str:
    """A leaf in a few words on one line (an object array's repr spans lines)."""
    if isinstance(leaf, np.ndarray):
        return f"{type(leaf).__name__} of dtype {leaf.dtype} and shape {leaf.shape}"
    text = " ".join(repr(leaf).split())
    return f"{type(leaf).__name__} {text[:60]}{'...' if len(text) > 60 else ''}"


def fits_batch(shape, batch) -> bool:
    """``shape`` broadcasts to the states' batch shape ``batch`` without enlarging it (one value
    per state, or one shared): a larger result would silently integrate other states than given."""
    try:
        return np.broadcast_shapes(tuple(shape), tuple(batch)) == tuple(batch)
    except ValueError:
        return False


def ravel(state):
    """(flat vector of the floating leaves, unravel) with ``unravel(v)`` the state whose
    floating leaves are read from ``v`` and whose integer leaves are those of ``state``."""
    leaves, treedef = jax.tree_util.tree_flatten(state)
    floating = [is_floating(leaf) for leaf in leaves]
    flat, unravel_floats = ravel_pytree([leaf for leaf, f in zip(leaves, floating) if f])

    def unravel(v):
        it = iter(unravel_floats(v))
        return jax.tree_util.tree_unflatten(treedef, [next(it) if f else leaf for leaf, f in zip(leaves, floating)])

    return flat, unravel


def leading_size(tree, name: str) -> int:
    """The common leading-axis length of every leaf (a batch or a trajectory)."""
    sizes = {int(np.shape(leaf)[0]) if np.ndim(leaf) else -1 for leaf in jax.tree_util.tree_leaves(tree)}
    if len(sizes) != 1 or -1 in sizes:
        raise InputError(f"every leaf of {name} needs the same leading axis, got leading sizes {sorted(sizes)}")
    return sizes.pop()
