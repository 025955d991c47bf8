"""How ``n`` steps are advanced, and what reverse mode stores: the three adjoints.

* ``"store"`` (default): memory O(n). Under reverse mode (``grad``, ``vjp``; seen at the
  call, also through a ``vmap`` inside the differentiated function) a Composition of
  reversible flows keeps one state in ``KEEP_EVERY`` steps and walks the steps back from each
  with the flows' fused ``step_back`` (``advance_stored_retraced``: the reversible adjoint's
  pass restarted at each kept state, so round-off is carried over fewer than 2·KEEP_EVERY
  steps, never over the run): gradients 2-3x the forward run
  (``benchmarks/results/gradients.md``). Otherwise (other steps,
  forward mode, a ``grad`` outside a ``jit`` of the user's, where the call sees no reverse
  mode) the differentiated ``lax.scan``, which rematerialises its step from the stored state
  (``jax.checkpoint`` per step: stacking every intermediate instead made XLA re-evaluate the
  step once per stacked residual).
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


# Reverse mode (grad, vjp) traces its inputs with JAX's linearizing tracer (JAX linearizes
# directly since 0.5), forward mode (jvp, jacfwd) with JVPTracer: what lets ``choose_adjoint``
# pick for a ts= run. The class is not exported, so it is recognised by name; were it renamed,
# nothing would be chosen and JAX's own error would remain (tests/test_validation.py fails then).
def reverse_mode(tree) -> bool:
    """Whether a leaf of ``tree`` is being linearized for reverse mode (grad, vjp), also
    under a ``vmap`` inside the differentiated function (a batch tracer's value)."""
    def linearized(leaf):
        while type(leaf).__name__ == "BatchTracer":
            leaf = leaf.val
        return type(leaf).__name__ == "LinearizeTracer"

    return any(linearized(leaf) for leaf in jax.tree_util.tree_leaves(tree))


def choose_adjoint(adjoint, step, ts_run: bool, inputs) -> str:
    """``adjoint`` checked, or the one that works: ``"store"``, except for a ``ts=`` run under
    reverse mode, whose loops of traced length only the reversible adjoint differentiates
    (``"reversible"`` for a splitting of reversible flows; for another step an ``InputError``)."""
    if adjoint is not None:
        return check_adjoint(adjoint, step)
    if ts_run and reverse_mode(inputs):
        try:
            return check_adjoint("reversible", step)
        except InputError:
            raise InputError(f"reverse-mode differentiation (grad, vjp) of integrate(..., ts=...) needs "
                             f"adjoint='reversible', a splitting of reversible flows, and a {type(step).__name__} "
                             "is not one: differentiate a run of n_steps instead, or use forward mode (jvp, "
                             "jacfwd)") from None
    return "store"


def check_adjoint(adjoint: str, step) -> str:
    if adjoint not in ADJOINTS:
        raise InputError(f"adjoint must be one of {ADJOINTS}, got {adjoint!r}")
    if adjoint == "reversible":
        if not isinstance(step, Composition):
            raise InputError("adjoint='reversible' needs a Composition (a splitting) of reversible flows, "
                             f"got {type(step).__name__}: use adjoint='checkpoint'")
        if not retraceable(step):
            bad = [type(f).__name__ for f in step.flows if not f.is_reversible]
            raise InputError(f"adjoint='reversible' needs flows with φ_-t = φ_t⁻¹ (exact group flows, or "
                             f"time-symmetric compositions of them); {', '.join(bad)} is not: use adjoint='checkpoint'")
    return adjoint


def advance(step, x, h, n, adjoint: str = "store"):
    """``n`` steps of ``step`` from ``x`` (a Python int or a traced integer count)."""
    if adjoint == "reversible":
        return advance_reversible(step, x, h, n)
    if adjoint == STORE_RETRACED:
        return advance_stored_retraced(step, x, h, n) if isinstance(n, int) and n >= 2 else advance_stored(step, x, h, n)
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


# ------------------------------------------------------------------ the stored adjoint, retraced
STORE_RETRACED = "store, retraced"
# The stored adjoint keeps one state in this many steps (``Composition.advance(keep=)``). Keeping
# every state, the forward pass wrote and the backward pass read the whole trajectory: on 10^3
# heavy tops at once (48 MB for 10^3 steps) that was most of what the gradient cost beyond the
# reversible one (3.13x the forward run against 2.61x); one in 16 leaves single-body runs as
# fast and their memory 16x smaller. The gradients agree with those from every state to
# round-off (tests/test_adjoints.py; a chaotic top over 10^4 steps: benchmarks/results/gradients.md).
KEEP_EVERY = 16


def retraceable(step) -> bool:
    """Whether ``Composition.retrace`` can walk ``step`` back: a Composition of reversible flows."""
    return isinstance(step, Composition) and all(f.is_reversible for f in step.flows)


def stored_engine(adjoint: str, step, inputs) -> str:
    """How ``"store"`` runs: under reverse mode, for a Composition of reversible flows,
    ``STORE_RETRACED`` (``advance_stored_retraced``: its gradient 2-3x the forward run, not
    3.5-10x); else as given. Seen at the call, before ``integrate``'s own jit: a reverse-mode
    transformation outside a jit of the user's (``grad(jit(f))``) is not seen, and the
    differentiated scan runs (the same gradient to round-off)."""
    if adjoint == "store" and retraceable(step) and reverse_mode(inputs):
        return STORE_RETRACED
    return adjoint


def advance_stored_retraced(step, x, h, n: int):
    """``n`` steps whose VJP keeps one state in ``KEEP_EVERY`` steps and walks the steps back
    from each with the flows' fused ``step_back`` (the reversible adjoint's pass, restarted at
    every kept state: round-off carried over fewer than 2·KEEP_EVERY steps). Used for
    ``"store"`` under reverse mode only: a ``jax.custom_vjp`` has no forward mode."""
    parameters, static = split_parameters(step)
    return _stored(static, n, KEEP_EVERY, parameters, x, h)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1, 2))
def _stored(static, n, every, parameters, x, h):
    return advance_stored(join_parameters(parameters, static), x, h, n)


def _stored_fwd(static, n, every, parameters, x, h):
    y, kept = join_parameters(parameters, static).advance(x, h, n, keep=every)
    return y, (parameters, y, kept, h)


def _stored_bwd(static, n, every, residuals, ct_y):
    parameters, y, kept, h = residuals
    _, ct_x, ct_parameters, ct_h = join_parameters(parameters, static).retrace(y, h, n, ct_y, kept=kept)
    return ct_parameters, ct_x, ct_h


_stored.defvjp(_stored_fwd, _stored_bwd)
