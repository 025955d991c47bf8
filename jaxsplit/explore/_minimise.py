"""Adam, then L-BFGS with a strong-Wolfe line search, as one ``lax.while_loop`` that evaluates the
loss and its gradient at exactly one place.

Why one place: XLA inlines every call site of a traced function, so each place that evaluates
the loss compiles the whole integrator, forward and reverse, once more. Adam's loop and the two
branches of optax's zoom line search (bracketing and zooming each evaluate) were three copies; a
fit's compilation was mostly those copies. Here every iteration of the loop picks the next point
to evaluate from its state (an Adam step, the line search's next trial step), evaluates there once,
and updates its state from the value and gradient it got.

L-BFGS (Nocedal & Wright, *Numerical Optimization*, 2nd ed., Alg. 7.4 and 7.5) keeps the last
``MEMORY`` pairs (s, y) with s·y > 0; its line search is their Alg. 3.5 (bracketing by doubling)
and 3.6 (zoom by safeguarded cubic interpolation) for the strong Wolfe conditions with
c₁ = 1e-4, c₂ = 0.9, or the approximate Wolfe conditions of Hager & Zhang (SIAM J. Optim. 16,
2005), which accept a step whose decrease is below the round-off of f. A line search that finds
no acceptable step in ``LINE_SEARCH_STEPS`` trials takes its best step with sufficient decrease,
or else drops the memory and retries along −∇f, and stops there if −∇f finds no decrease either
(the minimum is resolved to round-off). The loop's branches are selects, not ``lax.cond``: the
state is a few vectors, and every branch then compiles once.
"""

from typing import NamedTuple

import jax
import jax.flatten_util
import jax.numpy as jnp
import optax

MEMORY = 10  # (s, y) pairs kept (optax's and SciPy's default)
C1, C2 = 1e-4, 0.9  # sufficient decrease, curvature (strong Wolfe)
APPROX_DECREASE, APPROX_DELTA = 1e-6, 0.1  # Hager–Zhang's ε (relative to |f|) and δ (optax's defaults)
LINE_SEARCH_STEPS = 30  # trial steps per line search before it gives up on a direction
GROWTH = 2.0  # bracketing: the trial step doubles until it brackets an acceptable step

ADAM, BRACKET, ZOOM, DONE = 0, 1, 2, 3  # what the loop does with the value it evaluates next


class _State(NamedTuple):
    mode: jax.Array  # ADAM, BRACKET, ZOOM or DONE
    z: jax.Array  # the point evaluated next (flat)
    adam_k: jax.Array  # Adam steps taken
    adam: optax.OptState
    # the L-BFGS iterate, its value and gradient, the search direction and φ'(0) = ∇f·d
    x: jax.Array
    f: jax.Array
    g: jax.Array
    d: jax.Array
    slope0: jax.Array
    k: jax.Array  # L-BFGS iterations (accepted line searches)
    # the line search along d: trial step a; previous trial (bracketing) or the interval's
    # ends (zooming; lo always has sufficient decrease), each with φ and φ'; the trials so far
    a: jax.Array
    a_lo: jax.Array
    f_lo: jax.Array
    s_lo: jax.Array
    g_lo: jax.Array
    a_hi: jax.Array
    f_hi: jax.Array
    s_hi: jax.Array
    trials: jax.Array
    # the memory: rows of s and y (newest at ``newest``), 1 / s·y (0 marks an empty row)
    S: jax.Array
    Y: jax.Array
    rho: jax.Array
    newest: jax.Array
    evaluations: jax.Array  # of the loss and gradient so far


def _direction(g, S, Y, rho, newest):
    """−H∇f by the two-loop recursion over the memory (empty rows have ρ = 0 and drop out),
    H₀ = (s·y / y·y) I from the newest pair, or −∇f / max(1, |∇f|) without one."""
    m = rho.shape[0]
    order = (newest - jnp.arange(m)) % m  # newest first

    def first(q_alphas, i):
        j = order[i]
        alpha = rho[j] * jnp.vdot(S[j], q_alphas)
        return q_alphas - alpha * Y[j], alpha

    q, alphas = jax.lax.scan(first, g, jnp.arange(m))
    yy = jnp.vdot(Y[newest], Y[newest])
    have = rho[newest] > 0
    gamma = jnp.where(have, 1.0 / jnp.where(have, rho[newest] * yy, 1.0), 1.0 / jnp.maximum(1.0, jnp.linalg.norm(g)))

    def second(r, i):
        j = order[m - 1 - i]
        beta = rho[j] * jnp.vdot(Y[j], r)
        return r + (alphas[m - 1 - i] - beta) * S[j], None

    r = jax.lax.scan(second, gamma * q, jnp.arange(m))[0]
    return -r


def _cubic_step(a_lo, f_lo, s_lo, a_hi, f_hi, s_hi):
    """The minimiser of the cubic through both ends' values and slopes, if it lies well inside
    the interval (10 % from either end), else the midpoint (Nocedal & Wright, (3.59))."""
    d1 = s_lo + s_hi - 3 * (f_lo - f_hi) / (a_lo - a_hi)
    disc = d1 * d1 - s_lo * s_hi
    d2 = jnp.sign(a_hi - a_lo) * jnp.sqrt(jnp.maximum(disc, 0.0))
    a = a_hi - (a_hi - a_lo) * (s_hi + d2 - d1) / (s_hi - s_lo + 2 * d2)
    lo, hi = jnp.minimum(a_lo, a_hi), jnp.maximum(a_lo, a_hi)
    margin = 0.1 * (hi - lo)
    good = (disc >= 0) & jnp.isfinite(a) & (a > lo + margin) & (a < hi - margin)
    return jnp.where(good, a, 0.5 * (a_lo + a_hi))


def _select(which, a, b):
    """``a`` where ``which`` else ``b``, leaf by leaf (states of the same structure)."""
    return jax.tree_util.tree_map(lambda u, v: jnp.where(which, u, v), a, b)


def _search_step(st, f, g):
    """One trial of the line search along d, with the value f and gradient g at x + a d:
    (acceptable, the search's state for its next trial)."""
    a, slope = st.a, jnp.vdot(g, st.d)
    bad = ~jnp.isfinite(f) | ~jnp.isfinite(slope) | (f > st.f + C1 * a * st.slope0)
    # strong Wolfe, or Hager–Zhang's approximate Wolfe conditions: near the minimum the
    # decrease C1 a φ'(0) is below the round-off of f, which the exact test cannot see
    approximate = ((f <= st.f + APPROX_DECREASE * jnp.abs(st.f)) & (slope >= C2 * st.slope0)
                   & (slope <= (2 * APPROX_DELTA - 1) * st.slope0))
    acceptable = (~bad & (jnp.abs(slope) <= -C2 * st.slope0)) | (jnp.isfinite(f) & approximate)
    zooming = st.mode == ZOOM
    # bracketing: too high, or no lower than the last trial -> [last, a]; rising -> [a, last];
    # zooming: too high -> hi = a; else a is the new lo (hi = the old lo if the slope says so)
    up = bad | ((f >= st.f_lo) & (zooming | (st.trials > 0)))
    swap = ~up & (slope * (st.a_hi - st.a_lo) >= 0)
    new, old_lo, old_hi = (a, f, slope), (st.a_lo, st.f_lo, st.s_lo), (st.a_hi, st.f_hi, st.s_hi)
    lo = _select(up, (*old_lo, st.g_lo), (*new, g))
    hi = _select(up, new, _select(zooming, _select(swap, old_lo, old_hi), old_lo))
    # bracketing goes on (the step doubles) while the slope is negative and nothing failed
    bracketed = zooming | up | (slope >= 0)
    hi = _select(bracketed, hi, old_hi)
    a = jnp.where(bracketed, _cubic_step(*lo[:3], *hi), GROWTH * a)
    return acceptable, st._replace(mode=jnp.where(bracketed, ZOOM, BRACKET), a=a, z=st.x + a * st.d,
                                   a_lo=lo[0], f_lo=lo[1], s_lo=lo[2], g_lo=lo[3], a_hi=hi[0], f_hi=hi[1],
                                   s_hi=hi[2], trials=st.trials + 1)


def minimise_flat(fun, x0, adam_steps: int, adam_lr: float, max_iter: int, tol: float):
    """``adam_steps`` Adam steps, then up to ``max_iter`` L-BFGS iterations (until |∇f| < tol) on
    ``fun`` of a flat vector: (x, L-BFGS iterations, fun(x)). One evaluation site (module
    docstring)."""
    value_and_grad = jax.value_and_grad(fun)
    dtype, n = x0.dtype, x0.shape[0]
    zero, one, count = jnp.zeros((), dtype), jnp.ones((), dtype), jnp.zeros((), jnp.int32)
    opt = optax.adam(adam_lr)
    # every evaluation Adam and L-BFGS may make (a line search gives up after LINE_SEARCH_STEPS
    # trials and may retry once along −∇f), in int32
    max_evaluations = min(adam_steps + 1 + max_iter * 2 * LINE_SEARCH_STEPS, 2**31 - 1)

    def begin_search(st, x, f, g, k):
        """A line search from x along −H∇f (along −∇f, memory dropped, if that does not descend);
        DONE when ∇f is small, the iterations are spent or nothing descends."""
        d = _direction(g, st.S, st.Y, st.rho, st.newest)
        steepest = ~(jnp.vdot(g, d) < 0)
        d = jnp.where(steepest, -g / jnp.maximum(1.0, jnp.linalg.norm(g)), d)
        slope = jnp.vdot(g, d)
        done = (k >= max_iter) | (jnp.linalg.norm(g) < tol) | ~jnp.isfinite(f) | ~(slope < 0)
        return st._replace(mode=jnp.where(done, DONE, BRACKET), z=x + d, x=x, f=f, g=g, d=d, slope0=slope, k=k,
                           a=one, a_lo=zero, f_lo=f, s_lo=slope, g_lo=g, a_hi=zero, f_hi=f, s_hi=slope,
                           trials=count, rho=jnp.where(steepest, 0.0, st.rho))

    def body(st):
        f, g = value_and_grad(st.z)  # the one evaluation site
        f = f.astype(dtype)
        st = st._replace(evaluations=st.evaluations + 1)
        adam_phase = st.mode == ADAM
        adamming = adam_phase & (st.adam_k < adam_steps)
        updates, adam_state = opt.update(g, st.adam, st.z)
        stepped = st._replace(z=optax.apply_updates(st.z, updates), adam_k=st.adam_k + 1, adam=adam_state)
        # L-BFGS: accept this trial, or give up on the direction (take the best trial with
        # sufficient decrease, else drop the memory and retry along −∇f, or stop if that was it)
        acceptable, searching = _search_step(st, f, g)
        searched = ~adam_phase & acceptable
        give_up = ~adam_phase & ~acceptable & (searching.trials >= LINE_SEARCH_STEPS)
        accepting = searched | give_up & (st.a_lo > 0)
        retrying = give_up & ~accepting
        a, f_new, g_new = _select(searched, (st.a, f, g), (st.a_lo, st.f_lo, st.g_lo))
        s, y = a * st.d, g_new - st.g
        sy = jnp.vdot(s, y)
        keep = accepting & (sy > 0)  # a pair with s·y <= 0 would make H indefinite
        slot = jnp.where(keep, (st.newest + 1) % MEMORY, st.newest)
        memory = st._replace(S=st.S.at[slot].set(jnp.where(keep, s, st.S[slot])),
                             Y=st.Y.at[slot].set(jnp.where(keep, y, st.Y[slot])),
                             rho=jnp.where(retrying, 0.0, st.rho.at[slot].set(jnp.where(keep, 1 / sy, st.rho[slot]))),
                             newest=slot)
        x, f_new, g_new = _select(adam_phase, (st.z, f, g), _select(accepting, (st.x + s, f_new, g_new),
                                                                     (st.x, st.f, st.g)))
        begun = begin_search(memory, x, f_new, g_new, st.k + accepting)
        begun = begun._replace(mode=jnp.where(retrying & jnp.all(st.rho == 0), DONE, begun.mode))
        return _select(adamming, stepped, _select(adam_phase | accepting | retrying, begun, searching))

    nan = jnp.full((), jnp.nan, dtype)
    vec = jnp.zeros((n,), dtype)
    start = _State(mode=jnp.asarray(ADAM, jnp.int32), z=x0, adam_k=count, adam=opt.init(x0), x=x0, f=nan, g=vec,
                   d=vec, slope0=zero, k=count, a=zero, a_lo=zero, f_lo=nan, s_lo=zero, g_lo=vec, a_hi=zero,
                   f_hi=nan, s_hi=zero, trials=count, S=jnp.zeros((MEMORY, n), dtype),
                   Y=jnp.zeros((MEMORY, n), dtype), rho=jnp.zeros((MEMORY,), dtype), newest=count,
                   evaluations=count)

    # The loop's condition reads two of its variables (the mode and the evaluation count): XLA's
    # trip-count analysis, given a condition on one variable, clones everything that variable's
    # update depends on (here the whole loss and gradient), several times per compilation; it
    # took 40 % of a spin-lattice fit's compile time.
    def running(st):
        return (st.mode != DONE) & (st.evaluations < max_evaluations)

    end = jax.lax.while_loop(running, body, start)
    return end.x, end.k, end.f


def minimise(residuals, params, adam_steps: int, adam_lr: float, lbfgs_iter: int, tol: float):
    """Adam, then L-BFGS, on the mean squared ``residuals(params)`` (any PyTree of floats):
    (params, L-BFGS iterations, final loss), to trace inside a jit."""
    flat, unravel = jax.flatten_util.ravel_pytree(params)

    def loss(x):
        r = residuals(unravel(x))
        return jnp.mean(r * r)

    x, k, f = minimise_flat(loss, flat, adam_steps, adam_lr, lbfgs_iter, tol)
    return unravel(x), k, f
