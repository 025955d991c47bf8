"""How ``n`` steps are advanced, and what reverse mode stores: the three adjoints.

* ``"store"`` (default): a ``lax.scan``; reverse mode keeps every step's state, memory
  O(n), the fastest gradient while it fits. A ``Composition`` rematerialises its step from
  the stored state (``jax.checkpoint`` per step): stacking every intermediate instead made
  XLA re-evaluate the step once per stacked residual (free body: 90× the forward run, now
  2.5×; ``benchmarks/results/gradients.md``). Other steps keep their residuals.
* ``"checkpoint"``: blocks of B = ⌈√n⌉ steps under ``jax.checkpoint``; reverse mode stores one
  state per block and recomputes a block at a time: memory O(n/B + B) = O(√n), about one
  extra forward run of cost.
* ``"reversible"``: for a composition of reversible flows (φ_{−t} = φ_t⁻¹: exact group
  flows, or time-symmetric compositions of them) the backward pass rebuilds every state by
  stepping back from the last one instead of storing it (a ``jax.custom_vjp``): memory
  independent of n. ``Composition.retrace`` walks the applied sub-flows backwards, each
  flow's ``step_back`` giving the state before it and the pulled-back cotangent in one
  pass (a rotation fuses both and shares its cos and sin; a kick (``AbstractKick``) steps
  back by x − t·v and pulls back with one ``jax.vjp`` of its velocity; other flows use
  ``jax.vjp`` of one call). The scheme need not be symmetric: the word is inverted sub-flow by sub-flow.
  The rebuilt states differ from the forward ones by accumulated round-off only (measured
  in the tests and benchmarks). Forward-mode differentiation is not available through it.

Every advance takes a Python-int or a traced step count (the latter for output at
arbitrary times, where ``lax.fori_loop``/``while`` loops are not reverse-differentiable
except through the reversible adjoint, which defines its own backward pass).
"""

import functools
import math

import jax
import jax.numpy as jnp

from ._compose import Composition
from ._errors import InputError
from ._flows import join_parameters, split_parameters
from ._loops import plain_loops

ADJOINTS = ("store", "checkpoint", "reversible")


def check_adjoint(adjoint: str, step) -> str:
    if adjoint not in ADJOINTS:
        raise InputError(f"adjoint must be one of {ADJOINTS}, got {adjoint!r}")
    if adjoint == "reversible":
        if not isinstance(step, Composition):
            raise InputError("adjoint='reversible' needs a Composition (a splitting) of reversible flows, "
                             f"got {type(step).__name__}: use adjoint='checkpoint'")
        bad = [type(f).__name__ for f in step.flows if not f.is_reversible]
        if bad:
            raise InputError(f"adjoint='reversible' needs flows with φ_-t = φ_t⁻¹ (exact group flows, or "
                             f"time-symmetric compositions of them); {', '.join(bad)} is not: use adjoint='checkpoint'")
    return adjoint


def advance(step, x, h, n, adjoint: str = "store"):
    """``n`` steps of ``step`` from ``x`` (a Python int or a traced integer count)."""
    if adjoint == "reversible":
        return advance_reversible(step, x, h, n)
    if adjoint == "checkpoint" and isinstance(n, int):
        return advance_checkpointed(step, x, h, n)
    return advance_stored(step, x, h, n)


def advance_stored(step, x, h, n):
    if hasattr(step, "advance"):
        return step.advance(x, h, n)
    if isinstance(n, int):
        return x if n == 0 else jax.lax.scan(lambda y, _: (step(y, h), None), x, length=n)[0]
    return jax.lax.fori_loop(0, n, lambda _, y: step(y, h), x)


def advance_checkpointed(step, x, h, n: int, block: int | None = None):
    """⌊n/B⌋ blocks of B steps under ``jax.checkpoint`` (B = ⌈√n⌉ by default), then the rest."""
    block = max(1, math.isqrt(max(n, 1))) if block is None else block
    blocks, rest = divmod(n, block)
    run_block = jax.checkpoint(lambda y: advance_stored(step, y, h, block))
    x = jax.lax.scan(lambda y, _: (run_block(y), None), x, length=blocks)[0] if blocks else x
    return advance_stored(step, x, h, rest) if rest else x


# ------------------------------------------------------------------ the reversible adjoint
def advance_reversible(step, x, h, n):
    """``n`` steps whose VJP rebuilds the states by stepping back (O(1) memory)."""
    parameters, static = split_parameters(step)
    return _reversible(static, parameters, x, h, jnp.asarray(n, dtype=jnp.int32))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def _reversible(static, parameters, x, h, n):
    return advance_stored(join_parameters(parameters, static), x, h, n)


def _reversible_fwd(static, parameters, x, h, n):
    with plain_loops():  # under differentiation a nested loop call costs (``_one_kernel``)
        y = _reversible(static, parameters, x, h, n)
    return y, (parameters, y, h, n)


def _reversible_bwd(static, residuals, ct_y):
    parameters, y, h, n = residuals
    _, ct_x, ct_parameters, ct_h = join_parameters(parameters, static).retrace(y, h, n, ct_y)
    return ct_parameters, ct_x, ct_h, None


_reversible.defvjp(_reversible_fwd, _reversible_bwd)
