"""How ``n`` steps are advanced, and what reverse mode stores: the three adjoints.

* ``"store"`` (default): a ``lax.scan``; reverse mode keeps every step's residuals, memory
  O(n), the fastest gradient while it fits.
* ``"checkpoint"``: blocks of B = ⌈√n⌉ steps under ``jax.checkpoint``; reverse mode stores one
  state per block and recomputes a block at a time: memory O(n/B + B) = O(√n), about one
  extra forward run of cost.
* ``"reversible"``: for a time-symmetric composition of exact flows Ψ_{−h} = Ψ_h⁻¹, so the
  backward pass rebuilds every state by stepping back from the last one instead of storing
  it (a ``jax.custom_vjp``): memory independent of n. The rebuilt states differ from the
  forward ones by accumulated round-off only (measured in the tests and benchmarks).
  Forward-mode differentiation is not available through it (a custom VJP).

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

ADJOINTS = ("store", "checkpoint", "reversible")


def check_adjoint(adjoint: str, step) -> str:
    if adjoint not in ADJOINTS:
        raise InputError(f"adjoint must be one of {ADJOINTS}, got {adjoint!r}")
    if adjoint == "reversible":
        scheme = getattr(step, "scheme", None)
        if not isinstance(step, Composition) or scheme is None:
            raise InputError("adjoint='reversible' needs a Composition (a splitting) whose scheme is time-symmetric, "
                             f"got {type(step).__name__}")
        if not scheme.symmetric:
            raise InputError(f"adjoint='reversible' needs a time-symmetric scheme (Ψ_-h = Ψ_h⁻¹); {scheme.name!r} is "
                             "not: use a symmetric scheme, or adjoint='checkpoint'")
        bad = [type(f).__name__ for f in step.flows if not f.is_group]
        if bad:
            raise InputError(f"adjoint='reversible' needs exact group flows (φ_-t = φ_t⁻¹); {', '.join(bad)} is not")
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
def _split(step):
    from ._integrate import split_parameters

    return split_parameters(step)


def _join(parameters, static):
    from ._integrate import join_parameters

    return join_parameters(parameters, static)


def advance_reversible(step, x, h, n):
    """``n`` steps whose VJP rebuilds the states by stepping back (O(1) memory)."""
    parameters, static = _split(step)
    return _reversible(static, parameters, x, h, jnp.asarray(n, dtype=jnp.int32))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def _reversible(static, parameters, x, h, n):
    return advance_stored(_join(parameters, static), x, h, n)


def _reversible_fwd(static, parameters, x, h, n):
    y = _reversible(static, parameters, x, h, n)
    return y, (parameters, y, h, n)


def _add(a, b):
    return jax.tree_util.tree_map(lambda u, v: u + v, a, b)


def _reversible_bwd(static, residuals, ct_y):
    parameters, y, h, n = residuals

    def apply(p, state, size):
        return _join(p, static)(state, size)

    def back(carry):
        k, after, ct_x, ct_p, ct_h = carry
        before = apply(parameters, after, -h)  # Ψ_-h = Ψ_h⁻¹ rebuilds the earlier state
        _, vjp = jax.vjp(apply, parameters, before, h)
        dp, dx, dh = vjp(ct_x)
        return k + 1, before, dx, _add(ct_p, dp), ct_h + dh

    zeros_p = jax.tree_util.tree_map(jnp.zeros_like, parameters)
    start = (jnp.zeros((), jnp.int32), y, ct_y, zeros_p, jnp.zeros_like(h))
    _, _, ct_x, ct_p, ct_h = jax.lax.while_loop(lambda c: c[0] < n, back, start)
    return ct_p, ct_x, ct_h, None


_reversible.defvjp(_reversible_fwd, _reversible_bwd)
