"""The rotation kernel of a run, chosen inside the compiled program from a bound on its angles.

Every rotation's trigonometry is ``so3.half_turn``: valid for every angle, a reduction modulo
π and polynomials of 9 + 9 terms on |r| <= π/2 (float64). Most runs turn by far less (256
free bodies, h = 0.01: half angles below 0.01), where a few terms with no reduction are exact
to the same quarter epsilon: with them the direct call on 256 free bodies ran 2.1–2.6× faster
than with the general kernel alone (``benchmarks/results/against_before.md`` at 2857ec7 and
1f7e0c8, as imported). The choice must not depend on values
seen at the call (a user's ``jit``, ``vmap`` or ``grad`` hides them), so it is made in the
program: a run whose flows all declare a bound on their angles (``AbstractFlow.turn_rate``:
rotations of m, which every one of them keeps |m| of) computes the largest half angle any
sub-flow of the run can reach from the initial state and h, and ``jax.lax.switch`` runs the
loop traced with the shortest polynomial (``short_angles``) whose bound (``SHORT_LIMITS``)
covers it, else the general loop. Every loop is compiled; one runs.

Under ``vmap`` the bound is still one scalar for the whole batch (``largest``: its batching
rule reduces over the mapped axis too), so ``switch`` stays a branch and not a select of
every loop: a body integrated in a batch, under ``vmap`` or alone runs the same code where the
batch's angles are small, and the kernels agree to round-off where they differ.
"""

import contextlib
import contextvars
from fractions import Fraction

import jax
import jax.numpy as jnp
from jax.custom_batching import custom_vmap

# The bounds on |φ| with a loop of their own, shortest first; beyond the last, the general kernel.
# One: 6 + 5 terms in float64 for |φ| <= 1/4 (Kahan–Li 8 at h = 0.4 on the standard body, the
# work-precision study's coarse end, reaches ~0.08). A shorter tier (4 + 4 terms, |φ| <= 1/16) ran
# no faster and each tier is one more loop to compile (2026-11-27, 2000 steps at h = 0.01, median
# of 9: 256 free bodies 2.22 ms both, one body Kahan–Li 8 2.02 and 2.00 ms, 256 heavy tops 23.0 and
# 22.7 ms; compile 0.81 -> 0.46 s, 0.55 -> 0.38 s, 0.87 -> 0.74 s).
SHORT_LIMITS = (Fraction(1, 4),)

_SHORT = contextvars.ContextVar("jaxsplit_short_angles", default=None)


def short_angles():
    """The bound on |φ| that the rotation being traced may assume (``half_turn``), or None."""
    return _SHORT.get()


@contextlib.contextmanager
def setting(var, value):
    """``var`` (a ``contextvars.ContextVar``) set to ``value`` inside the block: the trace-time
    switches of ``core`` (this module's bound, ``_loops``' forms)."""
    token = var.set(value)
    try:
        yield
    finally:
        var.reset(token)


def assuming(limit):
    """Trace under ``short_angles() == limit`` (None: the general kernel). Also for a rule
    JAX traces after its call (``_loops._repeated``'s JVP), outside the ``cond`` that set it."""
    return setting(_SHORT, limit)


def largest(x):
    """max |x| over every entry, not differentiated; under ``vmap`` over the mapped axes as
    well (one scalar: ``_largest``'s batching rule)."""
    return _largest(jax.lax.stop_gradient(x))


@custom_vmap
def _largest(x):
    return jnp.max(jnp.abs(x), initial=0)


@_largest.def_vmap
def _largest_batched(axis_size, in_batched, x):
    # the mapped axis reduced with the others; a vmap around this one sees the result batched
    # along its own axis and reduces it in turn. (A JVP tracer reaching a custom_vmap recursed
    # without end under jacfwd: hence the stop_gradient in front.)
    return _largest(jnp.max(jnp.abs(x), initial=0)), False


def by_angle_bound(step, x, h, run, *operands):
    """``run(*operands)``, traced once per kernel where ``step`` (a flow) bounds its angles: under
    ``short_angles`` for each of ``SHORT_LIMITS``, and with the general kernel; ``lax.switch``
    picks the first whose bound covers the run's largest half angle |rate|·|m|·|weight·h|/2
    (from ``x``, the state the run starts from, and h). Where ``step`` declares no bound,
    ``run`` as it is."""
    rate = step.turn_rate(x)
    if rate is None or not SHORT_LIMITS:
        return run(*operands)
    half = rate * largest(h) / 2
    tier = sum((half > float(limit)).astype(jnp.int32) for limit in SHORT_LIMITS)

    def under(limit):
        def traced(*args):
            with assuming(limit):
                return run(*args)
        return traced

    tier = jnp.where(half <= float(SHORT_LIMITS[-1]), tier, len(SHORT_LIMITS))  # NaN (no comparison holds): general
    return jax.lax.switch(tier, [under(limit) for limit in SHORT_LIMITS + (None,)], *operands)

