"""``splitting(system, scheme, split)``: the system layer meets the composer.

The system supplies the exact flows of the split it offers; the scheme (data) says how to
compose them; the result is a ``Composition``, a pure ``step(state, h)``.
"""

from ..core._compose import Composition, compose
from ._base import AbstractSystem
from ._rigid_body import as_body
from ._spin_pairs import PairExchange, laid_out


def splitting(system, scheme, split: str | None = None, *, merge_flows: bool | None = None,
              **options) -> Composition:
    """One step ``step(x, h)`` of ``scheme`` on the exact flows of ``system``'s ``split``.

    ``system`` is any system of the system layer (a bare inertia is read as a
    ``RigidBody``); ``split`` defaults to the system's first offered split; ``options``
    go to the split (e.g. ``shift=1`` for the rigid body's Casimir split).

    >>> import jax.numpy as jnp, jaxsplit
    >>> step = jaxsplit.splitting(jaxsplit.RigidBody([2.0, 2.0, 1.0]), "strang")
    >>> m1 = step(jnp.array([0.6, 0.0, 0.8]), 0.1)
    """
    if not isinstance(system, AbstractSystem):
        system = as_body(system)
    step = compose(system.split(split, **options), scheme, merge_flows=merge_flows)
    # a split whose flows run on a layout of their own (a spin lattice's components first,
    # ``_spin_pairs``): the state converted once per call or run, not once per flow
    layout = getattr(system, "pair_layout", lambda: None)() if system.resolve_split(split, **options)[0] == "bonds" \
        else None
    return step if layout is None or not any(isinstance(f, PairExchange) for f in step.flows) else laid_out(step, layout)
