"""Invariant monitors along a trajectory: energy, Casimirs and any declared first integral.

For an invariant I and saved states x(t_k) (any PyTree), the error is e_k = I(x(t_k)) − I(x(t_0)).
``invariant_errors`` reports the absolute error |e_k|, the relative error |e_k|/|I(x_0)|,
their maxima, the final error, and the drift: the least-squares slope of e_k against t_k
(units of I per unit time). A bounded oscillating error (a symplectic splitting's energy)
has a drift near 0 over many periods; a secular one (explicit Euler, RK4 over long times)
does not. A vector-valued invariant (the spatial angular momentum Q m) is measured in the
max norm: |e_k| = max_i |I_i(x_k) − I_i(x_0)|, relative to max_i |I_i(x_0)|. The monitors
are pure ``jnp`` code (they jit and vmap).
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core._errors import InputError
from ..core._state import as_state, leading_size


class InvariantErrors(NamedTuple):
    """Errors of one invariant along a trajectory."""

    absolute: jax.Array  # |I(x_k) − I(x_0)| per saved state
    relative: jax.Array  # absolute / |I(x_0)| (inf where I(x_0) = 0)
    max_absolute: jax.Array
    max_relative: jax.Array
    final: jax.Array  # signed I(x_N) − I(x_0) (the largest component for a vector invariant)
    drift: jax.Array  # least-squares slope of I(x_k) − I(x_0) against t_k


def _unpack(trajectory, times):
    if times is None:
        if not (hasattr(trajectory, "t") and hasattr(trajectory, "x")):
            raise InputError("pass a Trajectory (t, x) or states together with times=")
        times, trajectory = trajectory.t, trajectory.x
    return jnp.asarray(times), as_state(trajectory, "the trajectory's states")


def invariant_errors(invariant: Callable, trajectory, times=None) -> InvariantErrors:
    """Errors of ``invariant`` (x -> scalar or vector) along ``trajectory`` (a ``Trajectory``,
    or states with a leading axis K (any PyTree) with ``times`` of shape (K,))."""
    t, xs = _unpack(trajectory, times)
    k = leading_size(xs, "the trajectory's states")
    if t.shape != (k,) or k < 1 or (isinstance(xs, jax.Array) and xs.ndim < 2):
        shape = getattr(xs, "shape", None) or jax.tree_util.tree_map(jnp.shape, xs)
        raise InputError(f"need K >= 1 states with K times, got states {shape} and times {t.shape}")
    values = jax.vmap(invariant)(xs).reshape(k, -1)
    e = values - values[0]
    absolute = jnp.max(jnp.abs(e), axis=1)
    relative = absolute / jnp.max(jnp.abs(values[0]))
    worst = jnp.argmax(jnp.abs(e[-1]))
    tc = t - jnp.mean(t)
    denom = jnp.sum(tc * tc)
    slopes = jnp.sum(tc[:, None] * (e - jnp.mean(e, axis=0)), axis=0) / jnp.where(denom > 0, denom, 1)
    drift = jnp.where(denom > 0, slopes[jnp.argmax(jnp.abs(slopes))], 0.0)
    return InvariantErrors(absolute, relative, jnp.max(absolute), jnp.max(relative), e[-1, worst], drift)


def _monitored(system) -> tuple:
    if hasattr(system, "invariants") and callable(system.invariants):
        return tuple(system.invariants().items())
    if hasattr(system, "monitored"):
        return system.monitored()
    raise InputError(f"no invariants known for {type(system).__name__}; use invariant_errors(f, ...)")


def monitor_invariants(system, trajectory, times=None) -> dict[str, InvariantErrors]:
    """Errors of every invariant of ``system`` (``system.invariants()``: the energy, the
    Casimirs and any other first integral) along ``trajectory``."""
    return {name: invariant_errors(f, trajectory, times) for name, f in _monitored(system)}
