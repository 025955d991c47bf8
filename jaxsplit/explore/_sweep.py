"""Batched sweeps: one scheme over many (initial state, system parameters, step size) cases.

Stable interface (the ``jaxsplit sweep`` CLI builds on it)::

    cases = sweep_cases(states=16, ratios=[(1.0, 0.5)], step_sizes=[0.1, 0.05])
    # or: sweep_cases(sampling="random", n_samples=1000, seed=0)
    # -> {"m0": (N, 3), "inertia": (N, 3), "h": (N,),
    #     "state_index", "ratio_index", "h_index": (N,) int (-1 for random samples)}

    out = sweep(scheme, cases, *, t_end, system=RigidBody, split=None,
                reference_scheme="kahan-li-8", reference_angle=0.1,
                chunk_size=1024, devices=None, **split_options)
    # -> {"<invariant>_error" (energy, casimir, ...), "error", "poisson_defect",
    #     "h", "n_steps", "m_final" (or "x_final"), "reference", "reference_accuracy"}

``system`` is a family ``params -> system`` (``RigidBody`` by default; any system of the
system layer, see ``jaxsplit.explore.batch``). ``cases`` holds the states ``x0`` (any
PyTree with a leading case axis; ``m0`` for the rigid body), the parameters ``params``
(``inertia`` for the rigid body) and the step sizes ``h``; a caller may cut the cases into
chunk files itself and call ``sweep`` per chunk.

Per case, with n = max(1, round(t_end / h)) steps of the exact size t_end / n (reported as
``h`` and ``n_steps``): for every invariant I of the system (``system.invariants()``: the
energy, the Casimirs, ...) ``<name>_error`` = max_k |I(x_k) − I(x_0)| / |I(x_0)| over every
step (absolute where I(x_0) = 0); ``error`` = max|x_n − x_ref(t_end)|; ``poisson_defect``
= max|DΦ Π DΦᵀ − Π(Φ(x_0))| of one step at x_0 (DΦ by ``jacfwd``, ``checks.poisson``).
The reference is ``reference_scheme`` on the system's ``reference_split`` (two rotations for
the rigid body) with the static step count that moves the fastest piece of the batch by at
most ``reference_angle`` per step (``batch.max_rate``); it is computed once per distinct
(x_0, params) and checked against a run with half the steps: ``reference_accuracy`` is that
difference (a bound on the reference's own error, which is smaller by about 2^order).

Memory stays bounded: cases are sorted by step count and run in padded chunks of
``chunk_size`` cases through ``jax.vmap`` and a ``lax.while_loop`` whose carry is the state
and the running maxima, so the device holds O(chunk_size) numbers, independent of the step
count and of N: XLA's ``memory_analysis`` of the compiled chunk gives about 0.7 KiB of
temporaries per case (8th-order word; 0.6 KiB for the reference kernel), i.e. < 1 MiB
for the default chunk of 1024, whatever the step count (checked in
``tests/test_sweep.py``). One compilation serves every chunk (all chunks are padded to
one shape) and every step size (h and the step count are traced); the composition word
runs as a scan (``roll``), so compile time does not grow with the scheme's length.

With several JAX devices (default: all of ``jax.devices()``) each chunk is sharded along
the case axis with ``jax.shard_map`` over a one-axis ``Mesh``; every case is computed by
the same per-device program, so the result equals the single-device result.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._bounds import available_memory, count, fits
from ..checks._poisson import poisson_defect
from ..core._compose import roll
from ..core._errors import InputError
from ..core._schemes import schemes
from ..systems._rigid_body import check_moments
from ..systems._splitting import splitting
from ._batch import (
    build,
    case_arrays,
    chunked,
    compiled,
    family_of,
    max_rate,
    ravel_rows,
    relative_change,
    resolve_devices,
    resolved_groups,
    take,
)

SAMPLINGS = ("grid", "random")
_REQUIRED = ("m0", "inertia", "h")


# ----------------------------------------------------------------------------- cases
def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform points on the unit sphere (Fibonacci lattice), shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _float_dtype(dtype):
    return np.dtype(jnp.result_type(float) if dtype is None else dtype)


def _ratios_array(ratios) -> np.ndarray:
    arr = np.asarray(ratios, dtype=float)
    if arr.ndim == 1 and arr.shape == (2,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) == 0:
        raise InputError(f"ratios must be pairs (I2/I1, I3/I1), shape (K, 2); got shape {arr.shape}")
    if not np.all(np.isfinite(arr) & (arr > 0)):
        raise InputError(f"inertia ratios must be positive and finite, got {arr.tolist()}")
    return arr


def _states_array(states) -> np.ndarray:
    if isinstance(states, (int, np.integer)) and not isinstance(states, bool):
        return fibonacci_sphere(count(states, "states"))
    arr = np.asarray(states, dtype=float)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3 or len(arr) == 0:
        raise InputError(f"states must be a count or an array of shape (K, 3), got shape {arr.shape}")
    norms = np.linalg.norm(arr, axis=1, keepdims=True)
    if not np.all(np.isfinite(arr)) or np.any(norms == 0):
        raise InputError("initial states must be finite and non-zero")
    return arr / norms


def _positive_vector(values, name) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or len(arr) == 0 or not np.all(np.isfinite(arr) & (arr > 0)):
        raise InputError(f"{name} must be positive finite numbers, got {np.asarray(values).tolist()}")
    return arr


# NumPy bytes per case while ``sweep_cases`` builds them: m0, inertia, h and three int64
# indices (80 B), the meshgrid's and the lattice's temporaries (about as much again), rounded up
BYTES_PER_CASE = 256


def _case_memory(n: int, what: str):
    """Refuse a set of cases that would not fit in the host's available memory."""
    fits(n * BYTES_PER_CASE, f"sweep_cases: {n:,} cases ({what})",
         f"at most {max(1, available_memory() // BYTES_PER_CASE):,} cases fit: sweep them in parts")


def physical(ratios) -> np.ndarray:
    """Mask of ratio pairs (I2/I1, I3/I1) whose body satisfies the triangle inequalities."""
    r = np.asarray(ratios, dtype=float)
    i = np.concatenate([np.ones_like(r[..., :1]), r], axis=-1)
    a, b, c = np.moveaxis(i, -1, 0)
    return (a + b >= c) & (b + c >= a) & (c + a >= b)


def sweep_cases(*, states=8, ratios=((1.0, 0.5),), step_sizes=(0.1,), sampling: str = "grid",
                n_samples: int | None = None, ratio_range=(0.3, 3.0), h_range=(0.01, 0.5),
                physical_only: bool = True, seed: int = 0, dtype=None) -> dict:
    """Cases for ``sweep``: initial states on |m| = 1, inertia I = (1, I2/I1, I3/I1), steps h.

    ``sampling="grid"``: the Cartesian product of ``states`` (a count for a Fibonacci
    lattice, or an array of directions, normalised), ``ratios`` (pairs (I2/I1, I3/I1)) and
    ``step_sizes``, ordered ratio-major, then h, then state; ``*_index`` give the position
    of each case in each axis, so ``out[key].reshape(K_ratios, K_h, K_states)`` works.
    A ratio pair of a non-physical body is refused (``RigidBody``'s policy) unless
    ``physical_only=False``.

    ``sampling="random"``: ``n_samples`` cases with m0 uniform on the sphere, each ratio
    log-uniform in ``ratio_range`` (rejecting non-physical bodies when ``physical_only``)
    and h log-uniform in ``h_range``; reproducible from ``seed``. Arrays in ``dtype``
    (default float): ``m0``, ``inertia`` (N, 3), ``h`` (N,), indices int (N,). The number of
    cases is refused before anything is built when they would not fit in the available memory
    (``BYTES_PER_CASE`` each).

    >>> import jaxsplit
    >>> cases = jaxsplit.sweep_cases(states=4, ratios=[(1.0, 0.5), (0.8, 0.6)], step_sizes=[0.1, 0.05])
    >>> cases["m0"].shape, cases["inertia"].shape, cases["h"].shape
    ((16, 3), (16, 3), (16,))
    """
    dt = _float_dtype(dtype)
    if sampling == "grid":
        r, h = _ratios_array(ratios), _positive_vector(step_sizes, "step_sizes")
        # a non-physical body is refused, as the constructors do (``check_moments``)
        check_moments(np.concatenate([np.ones((len(r), 1)), r], axis=1), "the ratios' body I",
                      not physical_only, "physical_only=False")
        n_states = count(states, "states") if np.ndim(states) == 0 else len(np.asarray(states))
        _case_memory(n_states * len(r) * len(h), f"{n_states:,} states x {len(r):,} ratios x {len(h):,} step sizes")
        s = _states_array(states)
        ri, hi, si = (a.ravel() for a in np.meshgrid(np.arange(len(r)), np.arange(len(h)),
                                                      np.arange(len(s)), indexing="ij"))
        m0, ratio, step = s[si], r[ri], h[hi]
    elif sampling == "random":
        n_samples = count(n_samples, "n_samples (random sampling)")
        _case_memory(n_samples, "n_samples")
        lo, hi_ = _positive_vector(ratio_range, "ratio_range")[[0, -1]]
        hlo, hhi = _positive_vector(h_range, "h_range")[[0, -1]]
        if not (lo <= hi_ and hlo <= hhi):
            raise InputError(f"ranges must be (low, high): ratio_range={ratio_range}, h_range={h_range}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError(f"seed must be an integer >= 0, got {seed!r}")
        rng = np.random.default_rng(seed)
        m0 = rng.standard_normal((n_samples, 3))
        m0 /= np.linalg.norm(m0, axis=1, keepdims=True)
        ratio = np.empty((0, 2))
        for _ in range(1000):
            draw = np.exp(rng.uniform(np.log(lo), np.log(hi_), (2 * n_samples, 2)))
            if physical_only:
                draw = draw[physical(draw)]
            ratio = np.concatenate([ratio, draw])[:n_samples]
            if len(ratio) == n_samples:
                break
        else:
            raise InputError(f"ratio_range {ratio_range} holds (almost) no physical bodies")
        step = np.exp(rng.uniform(np.log(hlo), np.log(hhi), n_samples))
        si = ri = hi = np.full(n_samples, -1)
    else:
        raise InputError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
    inertia = np.concatenate([np.ones((len(ratio), 1)), ratio], axis=1)
    return {"m0": m0.astype(dt), "inertia": inertia.astype(dt), "h": step.astype(dt),
            "state_index": si, "ratio_index": ri, "h_index": hi}


# ----------------------------------------------------------------------------- kernels
MAX_STEPS = 2**31 - 1  # the per-case step counter is an int32 (fits any float32/64 run)


def _case_kernel(family, scheme, split, options: tuple):
    """Per-case function (x0, params, h, n) -> (x_n, {invariant: max relative error}, defect)."""
    options = dict(options)

    def run(x0, params, h, n):
        system = family(params)
        step = roll(splitting(system, scheme, split, **options))
        invariants = system.invariants()
        initial = {k: f(x0) for k, f in invariants.items()}
        zero = jnp.zeros_like(h)  # derived from the inputs (varying under shard_map)

        def advance(carry):
            k, x, errs = carry
            x = step(x, h)
            errs = {key: jnp.maximum(errs[key], relative_change(invariants[key](x), initial[key])) for key in errs}
            return k + 1, x, errs

        start = (jnp.zeros_like(n), x0, {k: zero for k in invariants})
        _, x, errs = jax.lax.while_loop(lambda c: c[0] < n, advance, start)
        return x, errs, poisson_defect(step, system, x0, h)

    return jax.vmap(run)


def _reference_kernel(family, scheme, split, options: tuple):
    """Per-case reference (x0, params, t_end, n) -> (x(t_end) with n steps, with n/2).

    Both runs share one compiled step inside a ``while_loop`` (a traced step count: a
    refinement compiles nothing new), which keeps the compilation of long words short.
    """
    options = dict(options)

    def one(x0, params, t_end, n):
        step = roll(splitting(family(params), scheme, split, **options))
        h = t_end / n.astype(t_end.dtype)
        return jax.lax.while_loop(lambda c: c[0] < n, lambda c: (c[0] + 1, step(c[1], h)),
                                  (jnp.zeros_like(n), x0))[1]

    def run(x0, params, t_end, n_ref):
        counts = jnp.stack([n_ref, n_ref // 2])
        both = jax.vmap(one, in_axes=(None, None, None, 0))(x0, params, t_end, counts)
        return take(both, 0), take(both, 1)

    return jax.vmap(run)


def _rate_kernel(family, split, options: tuple):
    options = dict(options)

    def run(x0, params):
        system = family(params)
        return max_rate(system, system.split(split, **options), x0)

    return jax.vmap(run)


def reference_steps(rate, t_end: float, angle: float) -> int:
    """Static step count moving the fastest piece (``rate``) by <= ``angle`` per step."""
    omega = float(np.max(rate))
    n = max(16, math.ceil(t_end * max(omega, 1e-300) / angle))
    if n > MAX_STEPS:
        raise InputError(f"the reference would need {n:,} steps (> {MAX_STEPS:,}): t_end or the rates are too large")
    return n + (n % 2)


REFERENCE_TOL = 1e-12  # reference refined (x4 steps) until |run - half-step run| <= this x max|x|
MAX_REFINEMENTS = 3


def reference_solution(x0, params, t_end: float, *, system=None, scheme="kahan-li-8", split=None,
                       angle: float = 0.1, tol: float = REFERENCE_TOL, chunk_size: int = 1024, devices=None,
                       allow_nonphysical: bool = False, **split_options):
    """x(t_end) for each case (x0[i], params[i]) of the family ``system`` (default
    ``RigidBody``: x0 = m0 (N, 3), params = inertia (N, 3)), by ``scheme`` (8th order by
    default) on the system's ``reference_split`` (or ``split`` with ``split_options``) with
    steps moving the fastest piece by <= ``angle`` (``batch.max_rate``), refined (4x the
    steps, at most 3 times) while |run − run with half the steps| > ``tol`` max|x|; returns
    ``(reference, accuracy)``, ``accuracy`` being that difference (max norm per case).
    ``reference`` has the leaves of ``x0`` (leading axis N), ``accuracy`` is (N,); NumPy.

    >>> import numpy as np, jaxsplit
    >>> case = jaxsplit.STANDARD_CASE
    >>> ref, acc = jaxsplit.reference_solution(np.array([case.m0]), np.array([case.inertia]), case.t_end,
    ...                                        allow_nonphysical=True)            # (2, 1, 2/3): see STANDARD_CASE
    >>> bool(np.max(np.abs(ref[0] - np.array(case.reference))) < 1e-12), bool(acc[0] < 1e-12)
    (True, True)
    """
    family = family_of(system, allow_nonphysical)
    scheme = schemes.resolve(scheme)
    _, x0, params, _ = case_arrays({"x0": x0, "params": params, "h": np.ones(len(jax.tree_util.tree_leaves(x0)[0]))})
    build(family, params)  # validates the concrete batch
    devices = resolve_devices(devices)
    if split is None:
        split, split_options = build(family, take(params, 0)).reference_split
    rows = ravel_rows(x0)
    t = np.full(rows.shape[0], t_end, dtype=rows.dtype)
    scale = np.max(np.abs(rows), axis=1)
    fine, accuracy = None, np.empty(len(t))
    for name, opts, idx in resolved_groups(family, params, split, split_options):
        key = tuple(sorted(opts.items()))
        rate_fn = compiled(("rate", family, name, key), lambda name=name, key=key: _rate_kernel(family, name, key), None)
        rate = np.asarray(rate_fn(take(x0, idx), take(params, idx)))
        n_ref = reference_steps(rate, t_end, angle)
        fn = compiled(("ref", family, scheme, name, key),
                      lambda name=name, key=key: _reference_kernel(family, scheme, name, key), devices)
        for _ in range(MAX_REFINEMENTS + 1):
            counts = np.full(len(idx), n_ref, dtype=np.int32)
            f, c = chunked(fn, [take(x0, idx), take(params, idx), t[idx], counts], chunk_size, len(devices))
            acc = np.max(np.abs(ravel_rows(f) - ravel_rows(c)), axis=1)
            if np.all(acc <= tol * scale[idx]) or 4 * n_ref > MAX_STEPS:
                break
            n_ref *= 4
        if fine is None:
            fine = jax.tree_util.tree_map(lambda a: np.empty((len(t),) + a.shape[1:], a.dtype), f)
        jax.tree_util.tree_map(lambda d, s, idx=idx: d.__setitem__(idx, s), fine, f)
        accuracy[idx] = acc
    return fine, accuracy


def _check_t_end(t_end):
    if isinstance(t_end, bool) or not isinstance(t_end, (int, float, np.floating, np.integer)) or not (
            math.isfinite(t_end) and t_end > 0):
        raise InputError(f"t_end must be a positive number, got {t_end!r}")
    return float(t_end)


def sweep(scheme, cases: dict, *, t_end: float, system=None, split: str | None = None,
          reference_scheme="kahan-li-8", reference_angle: float = 0.1, chunk_size: int = 1024,
          devices=None, allow_nonphysical: bool = False, **split_options) -> dict:
    """Evaluate ``scheme`` on every case (see the module docstring for the inputs and outputs):
    a dict of NumPy arrays with a leading case axis N. The cases are traced (one compilation
    per chunk shape); ``scheme``, ``split`` and its options are static. ``allow_nonphysical``
    applies to the default family's bodies, as for ``RigidBody``.

    >>> import jaxsplit
    >>> cases = jaxsplit.sweep_cases(states=4, ratios=[(0.8, 0.6)], step_sizes=[0.1])
    >>> out = jaxsplit.sweep("strang", cases, t_end=1.0, split="casimir", shift=1)
    >>> out["casimir_error"].shape, bool(out["casimir_error"].max() < 1e-14), bool(out["poisson_defect"].max() < 1e-14)
    ((4,), True, True)
    """
    scheme = schemes.resolve(scheme)
    family = family_of(system, allow_nonphysical)
    t_end = _check_t_end(t_end)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise InputError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if isinstance(reference_angle, bool) or not isinstance(reference_angle, (int, float)) or not (
            0 < reference_angle <= 0.5):
        raise InputError(f"reference_angle must be in (0, 0.5], got {reference_angle!r}")
    state_key, x0, params, h = case_arrays(cases)
    build(family, params)  # validates the concrete batch
    devices = resolve_devices(devices)
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.rint(t_end / h)
    if not np.all(steps <= MAX_STEPS):
        raise InputError(f"a case needs {float(np.max(steps)):.3g} steps (t_end / h), more than the {MAX_STEPS:,} "
                         "a sweep runs per case; use a larger h or a shorter t_end")
    n_steps = np.maximum(1, steps).astype(np.int64)
    h_exact = (t_end / n_steps).astype(h.dtype)
    order = np.argsort(n_steps, kind="stable")  # homogeneous chunks: the loop runs max(n) of a chunk
    n = len(h)
    results = None
    for name, opts, idx in resolved_groups(family, params, split, split_options):
        idx = order[np.isin(order, idx)]
        key = tuple(sorted(opts.items()))
        fn = compiled(("case", family, scheme, name, key),
                      lambda name=name, key=key: _case_kernel(family, scheme, name, key), devices)
        part = chunked(fn, [take(x0, idx), take(params, idx), h_exact[idx], n_steps[idx].astype(np.int32)],
                       chunk_size, len(devices))
        if results is None:
            results = jax.tree_util.tree_map(lambda a: np.empty((n,) + a.shape[1:], a.dtype), part)
        jax.tree_util.tree_map(lambda d, s, idx=idx: d.__setitem__(idx, s), results, part)
    x_final, errors, defect = results

    # One reference per distinct (x0, params).
    keys = np.concatenate([ravel_rows(x0), ravel_rows(params)], axis=1)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    ref_u, acc_u = reference_solution(take(x0, first), take(params, first), t_end, system=family,
                                      scheme=reference_scheme, angle=reference_angle,
                                      chunk_size=chunk_size, devices=devices)
    reference = take(ref_u, inverse)
    final_key = {"m0": "m_final", "x0": "x_final"}[state_key]
    out = {f"{k}_error": v for k, v in errors.items()}
    return out | {
        "error": np.max(np.abs(ravel_rows(x_final) - ravel_rows(reference)), axis=1),
        "poisson_defect": defect, "h": h_exact, "n_steps": n_steps,
        final_key: x_final, "reference": reference, "reference_accuracy": acc_u[inverse],
    }
