"""Batched sweeps: one scheme over many (initial state, inertia, step size) cases.

Stable interface (the ``jaxsplit sweep`` CLI builds on it)::

    cases = sweep_cases(states=16, ratios=[(1.0, 0.5)], step_sizes=[0.1, 0.05])
    # or: sweep_cases(sampling="random", n_samples=1000, seed=0)
    # -> {"m0": (N, 3), "inertia": (N, 3), "h": (N,),
    #     "state_index", "ratio_index", "h_index": (N,) int (-1 for random samples)}

    out = sweep(scheme, cases, *, t_end, split="axes", shift_axis="auto",
                reference_scheme="kahan-li-8", reference_angle=0.1,
                chunk_size=1024, devices=None)
    # -> {"energy_error", "casimir_error", "error", "poisson_defect",
    #     "h", "n_steps", "m_final", "reference", "reference_accuracy"}: per-case arrays

``cases`` may be any dict holding at least ``m0`` (N, 3), ``inertia`` (N, 3) and ``h`` (N,)
(so a caller can split the cases into chunk files itself and call ``sweep`` per chunk).

Per case, with n = max(1, round(t_end / h)) steps of the exact size t_end / n (reported as
``h`` and ``n_steps``): ``energy_error`` = max_k |H(m_k)/H(m_0) − 1| and ``casimir_error``
= max_k |C(m_k)/C(m_0) − 1| over every step; ``error`` = max|m_n − m_ref(t_end)|;
``poisson_defect`` = max|DΦ Π DΦᵀ − Π(Φ(m_0))| of one step at m_0 (DΦ by ``jacfwd``).
The reference is the Casimir-split ``reference_scheme`` with the static step count that
turns the fastest rotation of the batch by at most ``reference_angle`` per step; it is
computed once per distinct (m_0, inertia) and checked against a run with half the steps:
``reference_accuracy`` is that difference (a bound on the reference's own error, which is
smaller by about 2^order).

Memory stays bounded: cases are sorted by step count and run in padded chunks of
``chunk_size`` cases through ``jax.vmap`` and a ``lax.while_loop`` whose carry is the state
and two running maxima, so the device holds O(chunk_size) numbers, independent of the step
count and of N: XLA's ``memory_analysis`` of the compiled chunk gives about 0.7 KiB of
temporaries per case (8th-order word; 0.6 KiB for the reference kernel), i.e. < 1 MiB
for the default chunk of 1024, whatever the step count (checked in
``tests/test_sweep.py``). The host holds the
inputs and outputs, 19 numbers (152 bytes in float64) per case; larger sweeps are split
into chunk files by the CLI. One compilation serves every chunk (all chunks are padded to
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
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from ._body import RigidBody
from ._compose import roll
from ._errors import InputError
from ._rotations import hat
from ._schemes import schemes
from ._splitting import SPLITS, splitting

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
        if states < 1:
            raise InputError(f"states must be a count >= 1 or an array (K, 3), got {states}")
        return fibonacci_sphere(int(states))
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

    ``sampling="random"``: ``n_samples`` cases with m0 uniform on the sphere, each ratio
    log-uniform in ``ratio_range`` (rejecting non-physical bodies when ``physical_only``)
    and h log-uniform in ``h_range``; reproducible from ``seed``.
    """
    dt = _float_dtype(dtype)
    if sampling == "grid":
        s, r, h = _states_array(states), _ratios_array(ratios), _positive_vector(step_sizes, "step_sizes")
        ri, hi, si = (a.ravel() for a in np.meshgrid(np.arange(len(r)), np.arange(len(h)),
                                                      np.arange(len(s)), indexing="ij"))
        m0, ratio, step = s[si], r[ri], h[hi]
    elif sampling == "random":
        if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
            raise InputError(f"random sampling needs n_samples >= 1, got {n_samples!r}")
        lo, hi_ = _positive_vector(ratio_range, "ratio_range")[[0, -1]]
        hlo, hhi = _positive_vector(h_range, "h_range")[[0, -1]]
        if not (lo <= hi_ and hlo <= hhi):
            raise InputError(f"ranges must be (low, high): ratio_range={ratio_range}, h_range={h_range}")
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
def _poisson_defect(step, m, h):
    """max|DΦ Π(m) DΦᵀ − Π(Φ(m))| for one step at m (Observation 3.1 of the seed paper)."""
    jac = jax.jacfwd(lambda y: step(y, h))(m)
    return jnp.max(jnp.abs(jac @ hat(m) @ jac.T - hat(step(m, h))))


def _case_kernel(scheme, split, shift):
    """Per-case function (m0, inertia, h, n) -> (m_n, energy err, Casimir err, defect)."""

    def run(m0, inertia, h, n):
        body = RigidBody(inertia)
        step = roll(splitting(body, scheme, split, shift_axis=shift))
        h0, c0 = body.hamiltonian(m0), body.casimir(m0)
        zero = jnp.zeros_like(h0)  # derived from the inputs (varying under shard_map)

        def advance(carry):
            k, m, de, dc = carry
            m = step(m, h)
            de = jnp.maximum(de, jnp.abs(body.hamiltonian(m) / h0 - 1))
            dc = jnp.maximum(dc, jnp.abs(body.casimir(m) / c0 - 1))
            return k + 1, m, de, dc

        _, m, de, dc = jax.lax.while_loop(lambda c: c[0] < n, advance, (jnp.zeros_like(n), m0, zero, zero))
        return m, de, dc, _poisson_defect(step, m0, h)

    return jax.vmap(run)


def _reference_kernel(scheme, shift, n_ref: int):
    """Per-case reference (m0, inertia, t_end) -> (m(t_end) with n_ref steps, with n_ref/2).

    Both runs share one compiled step inside a ``while_loop`` (a traced step count), which
    keeps the compilation of long high-order words short.
    """

    def one(m0, inertia, t_end, n):
        step = roll(splitting(RigidBody(inertia), scheme, "casimir", shift_axis=shift))
        h = t_end / n.astype(m0.dtype)
        return jax.lax.while_loop(lambda c: c[0] < n, lambda c: (c[0] + 1, step(c[1], h)),
                                  (jnp.zeros_like(n), m0))[1]

    def run(m0, inertia, t_end):
        counts = jnp.asarray([n_ref, n_ref // 2])
        both = jax.vmap(one, in_axes=(None, None, None, 0))(m0, inertia, t_end, counts)
        return both[0], both[1]

    return jax.vmap(run)


_COMPILED: dict = {}


def _compiled(key, build, devices):
    """jit(kernel) on one device, or jit(shard_map(kernel)) over a 1-D mesh of ``devices``."""
    full_key = (key, tuple(devices) if devices is not None else None)
    if full_key not in _COMPILED:
        fn = build()
        if devices is not None and len(devices) > 1:
            mesh = Mesh(np.asarray(devices), ("cases",))
            fn = jax.shard_map(fn, mesh=mesh, in_specs=P("cases"), out_specs=P("cases"))
        _COMPILED[full_key] = jax.jit(fn)
    return _COMPILED[full_key]


def _chunked(fn, arrays, chunk_size: int, multiple: int):
    """Apply ``fn`` to equal-shape chunks of ``arrays`` (padded with the last case)."""
    n = len(arrays[0])
    size = max(multiple, math.ceil(min(chunk_size, n) / multiple) * multiple)
    outs = []
    for start in range(0, n, size):
        piece = [a[start:start + size] for a in arrays]
        pad = size - len(piece[0])
        if pad:
            piece = [np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) for a in piece]
        res = fn(*piece)
        outs.append([np.asarray(r)[: size - pad] for r in res])
    return [np.concatenate(parts) for parts in zip(*outs)]


def _shift_axes(inertia: np.ndarray, shift_axis) -> np.ndarray:
    """Per-case 1-based shift axis: the middle 1/I for "auto", else the given axis."""
    if shift_axis == "auto":
        return np.argsort(1 / inertia, axis=1, kind="stable")[:, 1] + 1
    if shift_axis in (1, 2, 3):
        return np.full(len(inertia), shift_axis)
    raise InputError(f"shift_axis must be 1, 2, 3 or 'auto', got {shift_axis!r}")


def _grouped(axes: np.ndarray, run):
    """Run ``run(axis, index)`` for each distinct axis value; results scattered back in order."""
    results = None
    for axis in np.unique(axes):
        idx = np.nonzero(axes == axis)[0]
        part = run(int(axis), idx)
        if results is None:
            results = [np.empty((len(axes),) + p.shape[1:], p.dtype) for p in part]
        for r, p in zip(results, part):
            r[idx] = p
    return results


def _resolve_devices(devices):
    if devices is None:
        devices = jax.devices()
    devices = list(devices)
    if not devices:
        raise InputError("devices must hold at least one JAX device")
    return devices


def _check_cases(cases) -> tuple:
    if not isinstance(cases, dict) or any(k not in cases for k in _REQUIRED):
        raise InputError(f"cases must be a dict with keys {_REQUIRED} (see sweep_cases)")
    m0, inertia, h = (np.asarray(cases[k]) for k in _REQUIRED)
    dtype = np.result_type(m0.dtype, inertia.dtype, h.dtype)
    if not np.issubdtype(dtype, np.floating):
        dtype = np.dtype(jnp.result_type(float))
    m0, inertia, h = (a.astype(dtype) for a in (m0, inertia, h))
    n = len(h)
    if m0.shape != (n, 3) or inertia.shape != (n, 3) or h.shape != (n,) or n == 0:
        raise InputError(
            f"cases need m0 (N, 3), inertia (N, 3), h (N,) with N >= 1; got "
            f"{m0.shape}, {inertia.shape}, {h.shape}")
    for name, arr in (("m0", m0), ("inertia", inertia), ("h", h)):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"cases[{name!r}] must be finite")
    if np.any(inertia <= 0):
        raise InputError("cases['inertia'] must be positive")
    if np.any(h <= 0):
        raise InputError("cases['h'] must be positive step sizes")
    if np.any(np.linalg.norm(m0, axis=1) == 0):
        raise InputError("cases['m0'] must be non-zero")
    return m0, inertia, h


def reference_steps(m0, inertia, t_end: float, angle: float) -> int:
    """Static step count turning the fastest rotation of the batch by <= ``angle`` per step."""
    rates = (1 / inertia).max(axis=1) - (1 / inertia).min(axis=1)
    omega = float(np.max(np.linalg.norm(m0, axis=1) * rates))
    n = max(16, math.ceil(t_end * max(omega, 1e-300) / angle))
    return n + (n % 2)


def reference_solution(m0, inertia, t_end: float, *, scheme="kahan-li-8", angle: float = 0.1,
                       chunk_size: int = 1024, devices=None):
    """m(t_end) for each row of (m0, inertia), by a Casimir split of ``scheme`` (8th order
    by default) with steps turning the fastest rotation by <= ``angle``; returns
    ``(reference, accuracy)`` where ``accuracy`` is |run − run with half the steps|."""
    m0, inertia = np.asarray(m0), np.asarray(inertia)
    scheme = schemes.resolve(scheme)
    devices = _resolve_devices(devices)
    n_ref = reference_steps(m0, inertia, t_end, angle)
    t = np.full(len(m0), t_end, dtype=m0.dtype)
    # Any shift axis gives the same flow; the step bound above holds for every choice.
    fn = _compiled(("ref", scheme, n_ref), lambda: _reference_kernel(scheme, 2, n_ref), devices)
    fine, coarse = _chunked(fn, [m0, inertia, t], chunk_size, len(devices))
    return fine, np.max(np.abs(fine - coarse), axis=1)


def sweep(scheme, cases: dict, *, t_end: float, split: str = "axes", shift_axis="auto",
          reference_scheme="kahan-li-8", reference_angle: float = 0.1, chunk_size: int = 1024,
          devices=None) -> dict:
    """Evaluate ``scheme`` on every case (see the module docstring for the outputs)."""
    scheme = schemes.resolve(scheme)
    if split not in SPLITS:
        raise InputError(f"split must be one of {SPLITS}, got {split!r}")
    if not (isinstance(t_end, (int, float, np.floating)) and math.isfinite(t_end) and t_end > 0):
        raise InputError(f"t_end must be a positive number, got {t_end!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise InputError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if not (isinstance(reference_angle, (int, float)) and 0 < reference_angle <= 0.5):
        raise InputError(f"reference_angle must be in (0, 0.5], got {reference_angle!r}")
    m0, inertia, h = _check_cases(cases)
    devices = _resolve_devices(devices)
    n_steps = np.maximum(1, np.rint(t_end / h)).astype(np.int64)
    h_exact = (t_end / n_steps).astype(h.dtype)
    order = np.argsort(n_steps, kind="stable")  # homogeneous chunks: the loop runs max(n) of a chunk
    axes = _shift_axes(inertia, shift_axis) if split == "casimir" else np.zeros(len(h), int)

    def run(axis, idx):
        idx = order[np.isin(order, idx)]
        shift = axis if split == "casimir" else "auto"
        fn = _compiled(("case", scheme, split, shift), lambda: _case_kernel(scheme, split, shift), devices)
        res = _chunked(fn, [m0[idx], inertia[idx], h_exact[idx], n_steps[idx].astype(np.int32)], chunk_size, len(devices))
        return [r[np.argsort(idx)] for r in res]  # back to ascending case order

    m_final, de, dc, defect = _grouped(axes, run)

    # One reference per distinct (m0, inertia).
    keys = np.concatenate([m0, inertia], axis=1)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    ref_u, acc_u = reference_solution(uniq[:, :3], uniq[:, 3:], float(t_end), scheme=reference_scheme,
                                      angle=reference_angle, chunk_size=chunk_size, devices=devices)
    reference, accuracy = ref_u[inverse], acc_u[inverse]
    return {
        "energy_error": de, "casimir_error": dc,
        "error": np.max(np.abs(m_final - reference), axis=1),
        "poisson_defect": defect, "h": h_exact, "n_steps": n_steps,
        "m_final": m_final, "reference": reference, "reference_accuracy": accuracy,
    }
