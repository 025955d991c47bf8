"""What a trajectory says about itself: every invariant's error along it, and its distance to
the exact solution.

``invariant_values`` evaluates each of ``system.invariants()`` (the energy, the Casimirs and
any other first integral: |m|², Q m and QᵀQ of the free body with its attitude) at every
saved state, in float64 whatever the run's dtype, so a float32 run's drift is measured, not
rounded; ``relative_errors`` turns them into max|I − I0| / max|I0| per state (the absolute
change where I0 = 0; vectors and matrices in the max norm, as the sweeps report them);
``exact_states`` is the free body's elliptic solution (``exact_solution``) at the saved
times and ``state_errors`` the max-norm distance to it. Rows are padded to a power of two
(``bucket``) so that runs of similar length share one compilation. ``column_name`` turns an invariant's
label ("|Gamma|^2") into a name a file column can carry ("gamma_norm_sq").
"""

import functools
import re

import numpy as np


def _float64(states):
    import jax

    return jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=np.float64), states)


def bucket(n: int) -> int:
    """Rows padded to a power of two (at least 64): runs of similar length share one compilation."""
    return max(64, 1 << max(0, n - 1).bit_length())


def _padded(tree, n: int):
    """Every leaf's rows padded to ``bucket(n)`` by repeating the last row."""
    import jax

    extra = bucket(n) - n
    return jax.tree_util.tree_map(lambda a: np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]), tree)


@functools.lru_cache(maxsize=16)
def _invariants_kernel(system_type, labels):
    import jax

    def values(system, states):
        return jax.vmap(lambda x: {k: f(x) for k, f in system.invariants().items() if k in labels})(states)

    return jax.jit(values)


def invariant_values(system, states) -> dict:
    """{label: values (n, ...)} of every invariant at every saved state (float64)."""
    import jax

    states = _float64(states)
    n = len(jax.tree_util.tree_leaves(states)[0])
    labels = tuple(system.invariants())
    out = _invariants_kernel(type(system), labels)(system, _padded(states, n))
    return {label: np.asarray(out[label])[:n] for label in labels}


def relative_errors(values: dict) -> dict:
    """{label: (n,)}: max|I − I0| / max|I0| per state (absolute where I0 = 0)."""
    out = {}
    with np.errstate(over="ignore", invalid="ignore"):
        for label, v in values.items():
            flat = v.reshape(len(v), -1)
            diff = np.max(np.abs(flat - flat[:1]), axis=1)
            scale = np.max(np.abs(flat[0])) if len(flat) else 0.0
            out[label] = diff / scale if scale > 0 else diff
    return out


def exact_states(system, x0, t):
    """The free body's exact state at times ``t`` (n,) from ``x0`` (float64)."""
    import jax
    import jax.numpy as jnp

    from ..systems._exact import exact_solution

    x0 = tuple(jnp.asarray(p, jnp.float64) for p in x0) if isinstance(x0, tuple) else jnp.asarray(x0, jnp.float64)
    t = np.asarray(t, dtype=np.float64)
    out = exact_solution(system, x0, jnp.asarray(_padded(t, len(t))))
    return jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=np.float64)[: len(t)], out)


def state_errors(states, exact) -> np.ndarray:
    """max|x − x_exact| over every component, per saved state."""
    import jax

    pairs = zip(jax.tree_util.tree_leaves(_float64(states)), jax.tree_util.tree_leaves(exact))
    with np.errstate(over="ignore", invalid="ignore"):
        return np.max(np.concatenate([np.abs(a - b).reshape(len(a), -1) for a, b in pairs], axis=1), axis=1)


def column_name(label: str) -> str:
    """A file column for an invariant's label: |x|^2 -> x_norm_sq, <a,b> -> a_dot_b, Q^T -> qt."""
    name = re.sub(r"\|(\w+)\|\^2", r"\1_norm_sq", label)
    name = re.sub(r"<(\w+),(\w+)>", r"\1_dot_\2", name)
    name = re.sub(r"\^T", "t", name)
    return re.sub(r"[^0-9a-zA-Z]+", "_", name).strip("_").lower()
