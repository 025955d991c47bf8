"""Invariant monitors along a trajectory: energy and Casimir errors.

For an invariant I and saved states x(t_k), the error is e_k = I(x(t_k)) − I(x(t_0)).
``invariant_errors`` reports the absolute error |e_k|, the relative error |e_k|/|I(x_0)|,
their maxima, the final error, and the drift: the least-squares slope of e_k against t_k
(units of I per unit time). A bounded oscillating error (a symplectic splitting's energy)
has a drift near 0 over many periods; a secular one (explicit Euler, RK4 over long times)
does not. The monitors are pure ``jnp`` code (they jit and vmap).
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ._errors import InputError


class InvariantErrors(NamedTuple):
    """Errors of one invariant along a trajectory."""

    absolute: jax.Array  # |I(x_k) − I(x_0)| per saved state
    relative: jax.Array  # absolute / |I(x_0)| (inf where I(x_0) = 0)
    max_absolute: jax.Array
    max_relative: jax.Array
    final: jax.Array  # signed I(x_N) − I(x_0)
    drift: jax.Array  # least-squares slope of I(x_k) − I(x_0) against t_k


def _unpack(trajectory, times):
    if times is None:
        if not (hasattr(trajectory, "t") and hasattr(trajectory, "x")):
            raise InputError("pass a Trajectory (t, x) or states together with times=")
        return jnp.asarray(trajectory.t), jnp.asarray(trajectory.x)
    return jnp.asarray(times), jnp.asarray(trajectory)


def invariant_errors(invariant: Callable, trajectory, times=None) -> InvariantErrors:
    """Errors of ``invariant`` (x -> scalar) along ``trajectory`` (a ``Trajectory``, or
    states of shape (K, n) with ``times`` of shape (K,))."""
    t, xs = _unpack(trajectory, times)
    if xs.ndim < 2 or t.shape != xs.shape[:1] or t.shape[0] < 1:
        raise InputError(f"need K >= 1 states with K times, got states {xs.shape} and times {t.shape}")
    values = jax.vmap(invariant)(xs)
    e = values - values[0]
    absolute = jnp.abs(e)
    relative = absolute / jnp.abs(values[0])
    tc = t - jnp.mean(t)
    denom = jnp.sum(tc * tc)
    drift = jnp.where(denom > 0, jnp.sum(tc * (e - jnp.mean(e))) / jnp.where(denom > 0, denom, 1), 0.0)
    return InvariantErrors(absolute, relative, jnp.max(absolute), jnp.max(relative), e[-1], drift)


def _monitored(system) -> tuple:
    if hasattr(system, "monitored"):
        return system.monitored()
    if hasattr(system, "hamiltonian") and hasattr(system, "casimir"):  # RigidBody
        return (("energy", system.hamiltonian), ("casimir", system.casimir))
    raise InputError(f"no invariants known for {type(system).__name__}; use invariant_errors(f, ...)")


def monitor_invariants(system, trajectory, times=None) -> dict[str, InvariantErrors]:
    """Energy and Casimir (and any declared invariant) errors of ``system`` along ``trajectory``.

    ``system`` is a ``RigidBody`` (energy, casimir) or a ``HamiltonPoisson`` (energy and
    its declared invariants).
    """
    return {name: invariant_errors(f, trajectory, times) for name, f in _monitored(system)}
