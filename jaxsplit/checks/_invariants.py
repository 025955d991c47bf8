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
    """Errors of one invariant along a trajectory (see the module docstring).

    ``absolute``, ``relative``: (K,) per saved state; ``max_absolute``, ``max_relative``,
    ``final``, ``drift``: scalars; all in the states' floating dtype, all arrays (the
    monitors jit and vmap).

    >>> import jax.numpy as jnp, jaxsplit
    >>> e = jaxsplit.invariant_errors(lambda x: x @ x, jnp.array([[1.0, 0.0], [0.0, 1.1]]), jnp.array([0.0, 1.0]))
    >>> round(float(e.max_relative), 12), round(float(e.drift), 12)
    (0.21, 0.21)
    """

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
    """Errors of ``invariant`` (x -> scalar or vector) along ``trajectory``: an ``InvariantErrors``.

    ``trajectory`` is a ``Solution`` (its ``t`` and ``x``), or states with a leading axis K
    (any PyTree) together with ``times`` of shape (K,). Pure ``jnp``: traced throughout.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> sol = jaxsplit.integrate(jaxsplit.splitting(body, "strang", "casimir", shift=1),
    ...                          jnp.array([0.6, 0.0, 0.8]), 0.1, 100, save_every=10)
    >>> float(jaxsplit.invariant_errors(body.casimir, sol).max_relative) < 1e-14
    True
    """
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
    Casimirs and any other first integral) along ``trajectory``: {name: ``InvariantErrors``}.
    ``trajectory`` and ``times`` as for ``invariant_errors``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> sol = jaxsplit.integrate(jaxsplit.rk4(body), jnp.array([0.6, 0.0, 0.8]), 0.1, 100, save_every=10)
    >>> errors = jaxsplit.monitor_invariants(body, sol)
    >>> sorted(errors), float(errors["casimir"].max_relative) > 1e-9     # RK4 drifts off the sphere
    (['casimir', 'energy'], True)
    """
    return {name: invariant_errors(f, trajectory, times) for name, f in _monitored(system)}
