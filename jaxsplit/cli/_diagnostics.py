"""What a trajectory says about itself: every invariant's error along it, and its distance to
the exact solution.

``invariant_values`` evaluates each of ``system.invariants()`` (the energy, the Casimirs and
any other first integral: |m|², Q m and QᵀQ of the free body with its attitude) at every
saved state, in float64 whatever the run's dtype, so a float32 run's drift is measured, not
rounded; ``relative_errors`` turns them into max|I − I0| / max|I0| per state (the absolute
change where I0 = 0; vectors and matrices in the max norm, as the sweeps report them);
``exact_states`` is the free body's elliptic solution (``exact_solution``) at the saved
times and ``state_errors`` the max-norm distance to it. ``column_name`` turns an invariant's
label ("|Gamma|^2") into a name a file column can carry ("gamma_norm_sq").
"""

import re

import numpy as np


def _float64(states):
    import jax

    return jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=np.float64), states)


def invariant_values(system, states) -> dict:
    """{label: values (n, ...)} of every invariant at every saved state (float64)."""
    import jax

    states = _float64(states)
    return {label: np.asarray(jax.jit(jax.vmap(f))(states)) for label, f in system.invariants().items()}


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
    import jax.numpy as jnp

    from ..systems._exact import exact_solution

    x0 = tuple(jnp.asarray(p, jnp.float64) for p in x0) if isinstance(x0, tuple) else jnp.asarray(x0, jnp.float64)
    return _float64(exact_solution(system, x0, jnp.asarray(t, jnp.float64)))


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
