"""Learning composition coefficients with optax, order conditions kept exactly.

Family: symmetric compositions of the Strang step S_h with an odd number s = 2k + 1 of
stages, Ψ_h = S_{γ_s h} ∘ … ∘ S_{γ_1 h}, γ a palindrome (v_1 … v_k, c, v_k … v_1). For a
symmetric order-2 base, order 4 needs exactly Σγ = 1 and Σγ³ = 0 (Yoshida 1990; GNI
§V.3.2). Both are homogeneous but the first, so

    c = −∛(2 Σ v_i³),    γ = (v, c, v reversed) / (2 Σ v_i + c)

satisfies them for EVERY v (to round-off), and γ does not change when v is scaled: the
free parameters are z = (v_2, …, v_k) / v_1, k − 1 of them (1 for five stages, the family
that contains Suzuki's fractal, z = 1, and McLachlan's SS5, z ≈ 2.234). There is nothing
to penalise and no projection.

Objective on a training set of (body, m0) cases at a fixed step size: the mean over cases
of log(|error|² / |baseline error|²), the error being the Euclidean error at ``t_end``
against ``reference_solution`` and the baseline that of the starting scheme: twice the log
of the ratio of geometric-mean errors, so every body counts by its relative improvement
and none dominates (the error vector has three components, so |error|² does not cross 0). A coarse scan over z picks the start (the
landscape has several valleys), then Adam refines it (optax).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._bounds import MAX_STAGES, WHY_STAGES, at_most, count, fits
from ..core._errors import InputError
from ..core._schemes import Scheme
from ..core._state import as_state, leading_size
from ..systems._splitting import splitting
from ._batch import build, family_of
from ._sweep import reference_solution


def order4_coefficients(z):
    """Palindromic γ of an order-4 symmetric composition from the free parameters ``z``.

    ``z`` (k − 1,) gives s = 2k + 1 stages; works on numpy and JAX arrays (differentiable:
    traced ``z`` gives traced weights). The weights sum to 1 and Σγ³ = 0 for every ``z``.

    >>> import numpy as np, jaxsplit
    >>> g = jaxsplit.order4_coefficients(np.array([1.0]))                # Suzuki's fractal (5 stages)
    >>> np.allclose(g, jaxsplit.schemes["suzuki-5"].coefficients), round(float(np.sum(g ** 3)), 15)
    (True, 0.0)
    """
    xp = jnp if isinstance(z, (jax.Array, jax.core.Tracer)) else np
    z = xp.asarray(z)
    v = xp.concatenate([xp.ones((1,), z.dtype), z])
    cube = 2 * xp.sum(v**3)
    c = -xp.sign(cube) * xp.abs(cube) ** (1 / 3)
    s = 2 * xp.sum(v) + c
    return xp.concatenate([v, c[None], v[::-1]]) / s


def order4_parameters(gammas) -> np.ndarray:
    """Inverse of ``order4_coefficients`` for a published palindrome (checks the family)."""
    g = np.asarray(gammas, dtype=float)
    if g.ndim != 1 or len(g) % 2 == 0 or len(g) < 5 or not np.allclose(g, g[::-1], rtol=0, atol=1e-14):
        raise InputError(f"need an odd palindrome of >= 5 weights, got {g.tolist()}")
    return g[1:len(g) // 2] / g[0]


def _composed(strang, gammas, m, h):
    return jax.lax.scan(lambda y, g: (strang(y, g * h), None), m, gammas)[0]


class TunedScheme(NamedTuple):
    """Outcome of ``tune_scheme``: the learned ``scheme`` (a validated, usable ``Scheme``), its
    free parameters ``z`` and the start, the final ``loss``, the Adam ``history`` and, for
    one-parameter families, the coarse scan (NumPy arrays). See ``tune_scheme`` for a run.

    >>> import jaxsplit
    >>> jaxsplit.TunedScheme._fields[:4]
    ('scheme', 'z', 'start_z', 'loss')
    """

    scheme: Scheme  # the learned method, a validated Scheme (order 4, symmetric)
    z: np.ndarray  # free parameters
    start_z: np.ndarray
    loss: float  # final training objective (0 = as good as the start)
    history: np.ndarray  # objective per Adam iteration
    scan_z: np.ndarray  # coarse scan (1-parameter families only; else empty)
    scan_loss: np.ndarray


def _check_set(params, states, family):
    params = jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=float), params)
    states = jax.tree_util.tree_map(np.asarray, as_state(states, "states"))
    n = leading_size(params, "the training parameters")
    if leading_size(states, "states") != n:
        raise InputError(f"states must hold one state per training system ({n}) along the leading axis")
    if not all(np.all(np.isfinite(a)) for a in jax.tree_util.tree_leaves((params, states))):
        raise InputError("training parameters and states must be finite")
    build(family, params)  # validates the concrete batch
    return params, states


def tune_scheme(params, states, *, system=None, stages: int = 5, t_end: float = 10.0, n_steps: int = 40,
                split: str | None = "axes", start=None, iterations: int = 200, learning_rate: float = 0.02,
                scan_points: int = 201, scan_range=(-3.0, 3.0), name: str | None = None,
                allow_nonphysical: bool = False, **split_options) -> TunedScheme:
    """Learn an order-4, ``stages``-stage symmetric composition of Strang for the training
    systems ``system(params[i])`` (default ``RigidBody``: ``params`` are inertias (n, 3),
    physical unless ``allow_nonphysical``) started at ``states`` (leading axis n), integrated
    to ``t_end`` with ``n_steps`` steps.
    ``start`` (free parameters, default Suzuki's fractal, z = 1) is also the baseline of the
    objective; with one free parameter a scan over ``scan_range`` of ``scan_points`` values
    picks the start if it beats ``start``. The systems are traced (one compilation for the
    whole set), so split options must be explicit (the rigid body's Casimir split needs
    ``shift=0, 1 or 2``, not "auto"). ``params`` and ``states`` have a leading axis n (NumPy
    or JAX); the result's scheme is registered nowhere: pass it to ``splitting``.

    >>> import jaxsplit
    >>> inertia, m0 = jaxsplit.random_bodies(4, seed=1)
    >>> tuned = jaxsplit.tune_scheme(inertia, m0, t_end=2.0, n_steps=8, iterations=5, scan_points=11)
    >>> tuned.scheme.order, tuned.scheme.stages, tuned.loss <= 0.0       # never worse than its start
    (4, 5, True)
    """
    if not (isinstance(stages, int) and stages >= 5 and stages % 2 == 1):
        raise InputError(f"stages must be an odd integer >= 5 (3 stages leave no freedom), got {stages!r}")
    at_most(stages, MAX_STAGES, "stages", WHY_STAGES)
    iterations = count(iterations, "iterations", 0, 2**31 - 1, "a lax.scan length, counted in int32")
    scan_points = count(scan_points, "scan_points", 0, 2**31 - 1, "the objective is evaluated at every point")
    fits(scan_points * 64, f"a scan of {scan_points:,} points", "give fewer scan_points")
    family = family_of(system, allow_nonphysical)
    if any(isinstance(v, str) and v == "auto" for v in split_options.values()):
        raise InputError("tune_scheme runs every training system in one traced batch: give explicit split "
                         f"options, not 'auto' (got {split_options})")
    n_steps = count(n_steps, "n_steps")
    params, states = _check_set(params, states, family)
    first = build(family, jax.tree_util.tree_map(lambda a: a[0], params))
    first.split(split, **split_options)  # a clear error now for an unknown split or option
    k = (stages - 1) // 2
    dtype = jnp.result_type(float)
    start = np.ones(k - 1) if start is None else np.asarray(start, dtype=float).reshape(-1)
    if start.shape != (k - 1,):
        raise InputError(f"start must hold {k - 1} free parameters for {stages} stages, got {start.shape}")
    reference, _ = reference_solution(jax.tree_util.tree_map(lambda a: a.astype(dtype), states),
                                      jax.tree_util.tree_map(lambda a: a.astype(dtype), params), float(t_end),
                                      system=family)
    ref = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), reference)
    batch = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), params)
    x0s = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), states)
    h = jnp.asarray(t_end / n_steps, dtype)

    def errors(z):
        gammas = order4_coefficients(z)

        def one(p, x0, r):
            strang = splitting(family(p), "strang", split, **split_options)
            x = jax.lax.fori_loop(0, n_steps, lambda _, y: _composed(strang, gammas, y, h), x0)
            return sum(jnp.sum((a - b) ** 2) for a, b in zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(r)))

        return jax.vmap(one)(batch, x0s, ref)

    errors = jax.jit(errors)
    base = errors(jnp.asarray(start, dtype))

    def objective(z):
        return jnp.mean(jnp.log(errors(z) / base))

    scan_z = scan_loss = np.empty(0)
    z0 = jnp.asarray(start, dtype)
    if k == 2 and scan_points:
        scan_z = np.linspace(*scan_range, scan_points)
        scan_loss = np.asarray(jax.jit(jax.vmap(lambda z: objective(z[None])))(jnp.asarray(scan_z, dtype)))
        best = int(np.nanargmin(scan_loss))
        if scan_loss[best] < 0:
            z0 = jnp.asarray(scan_z[best:best + 1], dtype)

    opt = optax.adam(learning_rate)
    # forward mode: z holds a few parameters, and a jvp per parameter compiles far faster than
    # the reverse pass through the step loop
    def value_and_grad(z):
        def value_twice(z):  # the value as jacfwd's aux: one evaluation gives both
            v = objective(z)
            return v, v

        g, v = jax.jacfwd(value_twice, has_aux=True)(z)
        return v, g

    @jax.jit
    def run(z):
        def body(carry, _):
            z, state, best_z, best_v = carry
            v, g = value_and_grad(z)
            better = v < best_v
            best_z = jnp.where(better, z, best_z)
            best_v = jnp.where(better, v, best_v)
            updates, state = opt.update(g, state, z)
            return (optax.apply_updates(z, updates), state, best_z, best_v), v

        init = (z, opt.init(z), z, jnp.asarray(jnp.inf, dtype))
        (z, _, best_z, best_v), hist = jax.lax.scan(body, init, length=iterations)
        v_last = objective(z)
        return jnp.where(v_last < best_v, z, best_z), jnp.minimum(v_last, best_v), hist

    z, loss, history = run(z0)
    gammas = np.asarray(order4_coefficients(np.asarray(z, dtype=float)))
    label = name or f"tuned-ss{stages}-order4"
    scheme = Scheme(label, 4, "symmetric", tuple(float(g) for g in gammas),
                    f"learned with optax (jaxsplit.tune_scheme) on {leading_size(params, 'params')} systems, "
                    f"h = {float(t_end / n_steps):.4g}, split {split}")
    return TunedScheme(scheme, np.asarray(z), np.asarray(start), float(loss), np.asarray(history),
                       scan_z, scan_loss)


def random_bodies(n: int, *, seed: int = 0, ratio_range=(0.4, 2.5)):
    """``n`` physical bodies I = (1, I2/I1, I3/I1) (log-uniform ratios in ``ratio_range``) and unit
    m0: NumPy (n, 3) and (n, 3), reproducible from ``seed``.

    >>> import numpy as np, jaxsplit
    >>> inertia, m0 = jaxsplit.random_bodies(3)
    >>> inertia.shape, bool(np.allclose(np.linalg.norm(m0, axis=1), 1.0)), inertia[:, 0].tolist()
    ((3, 3), True, [1.0, 1.0, 1.0])
    """
    if not (isinstance(n, int) and n >= 1):
        raise InputError(f"n must be an integer >= 1, got {n!r}")
    from ._sweep import sweep_cases

    cases = sweep_cases(sampling="random", n_samples=n, seed=seed, ratio_range=ratio_range,
                        h_range=(1.0, 1.0))
    return np.asarray(cases["inertia"]), np.asarray(cases["m0"])


