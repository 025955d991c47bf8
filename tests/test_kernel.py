"""The rotation kernel: one straight-line trigonometry (``so3.half_turn``) valid for every angle,
accurate to round-off, and the same compiled program whether ``integrate`` is called directly
or under the caller's ``jit``, ``vmap`` or ``grad``."""

import collections
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.systems import so3

KERNEL_ULPS = 2  # |cos, sin − NumPy's| in units of the dtype's eps, up to the common sign
UNIT_CIRCLE_ULPS = 3  # c² + s² − 1, at every angle
COS_SIN_ULPS = 6  # cos_sin's exact-sign pair (one more rounding: 1 − 2s², 2sc)
CASIMIR_TOL = 1e-12  # relative, 1e5 steps
ROUNDOFF = 1e-13

STANDARD = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
M0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)


def _errors(phi, dtype):
    # a fresh function: jit's cache would keep a kernel traced under another ``assuming``
    c, s = (np.asarray(a, np.float64) for a in jax.jit(lambda p: so3.half_turn(p))(jnp.asarray(phi, dtype)))
    exact = np.asarray(jnp.asarray(phi, dtype), np.float64)
    cos, sin = np.cos(exact), np.sin(exact)
    sign = np.sign(c * cos + s * sin)  # one sign for both: rotations use 2sc and 2s² only
    eps = float(jnp.finfo(dtype).eps)
    return (np.max(np.abs(sign * c - cos)) / eps, np.max(np.abs(sign * s - sin)) / eps,
            np.max(np.abs(c * c + s * s - 1)) / eps, set(np.unique(np.abs(sign))))


@pytest.mark.parametrize("dtype, reach", [(jnp.float64, 1e4), (jnp.float64, 1e8), (jnp.float64, 1e12), (jnp.float32, 1e4)])
def test_the_kernel_is_accurate_to_round_off_at_every_resolved_angle(dtype, reach):
    # with or without fused multiply-adds (the suite compiles unoptimised: none are formed)
    phi = np.random.default_rng(0).uniform(-reach, reach, 100_001)
    phi[:6] = [math.pi / 2, -math.pi / 2, 1.5 * math.pi, 0.0, -0.0, 2.5 * math.pi]  # the reduction's joints
    cos_err, sin_err, unit, signs = _errors(phi, dtype)
    assert signs == {1.0}
    assert cos_err <= KERNEL_ULPS and sin_err <= KERNEL_ULPS and unit <= UNIT_CIRCLE_ULPS
    assert jax.jit(so3.half_turn)(jnp.asarray(phi, dtype))[0].dtype == dtype


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_beyond_the_resolved_angles_the_pair_stays_on_the_unit_circle(dtype):
    """Where φ's own rounding exceeds π (float32 from ~1e7, float64 from ~1e15) no angle is
    resolved, but a rotation must still be a rotation: c² + s² = 1 to round-off."""
    phi = np.random.default_rng(1).uniform(-1e30, 1e30, 10_001)
    _, _, unit, _ = _errors(phi, dtype)
    assert unit <= UNIT_CIRCLE_ULPS
    c, s = so3.half_turn(jnp.asarray([jnp.nan, jnp.inf], dtype))
    assert bool(jnp.all(jnp.isnan(c)) & jnp.all(jnp.isnan(s)))  # not finite in, not finite out


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_cos_sin_has_exact_signs(dtype):
    theta = np.linspace(-20.0, 20.0, 40_001)
    c, s = (np.asarray(a, np.float64) for a in so3.cos_sin(jnp.asarray(theta, dtype)))
    exact = np.asarray(jnp.asarray(theta, dtype), np.float64)
    eps = float(jnp.finfo(dtype).eps)
    assert np.max(np.abs(c - np.cos(exact))) <= COS_SIN_ULPS * eps
    assert np.max(np.abs(s - np.sin(exact))) <= COS_SIN_ULPS * eps


def _taylor_terms(limit: float, offset: int, eps: float) -> int:
    """Terms of the truncated Taylor series of cos (offset 0) or sin/φ (1): up to the first below eps/4 at limit."""
    k = 0
    while limit ** (2 * k) / math.factorial(2 * k + offset) > eps / 4:
        k += 1
    return k


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_the_economized_polynomials_are_shorter_than_the_taylor_series(dtype):
    _, _, bound, cos_c, sin_c = so3._kernel_constants(dtype)
    eps = float(np.finfo(dtype).eps)
    taylor = _taylor_terms(bound, 0, eps), _taylor_terms(bound, 1, eps)
    assert len(cos_c) <= taylor[0] and len(sin_c) <= taylor[1] and len(cos_c) + len(sin_c) < sum(taylor)
    assert np.dtype(dtype).type(cos_c[0]) == 1 and np.dtype(dtype).type(sin_c[0]) == 1  # exact at φ = 0
    assert math.pi / 2 < bound < math.pi / 2 * 1.02  # the reduced range and its rounding margin


def test_large_angles_keep_the_structure_and_agree_with_xlas_cos_and_sin():
    """Steps whose rotations turn by several radians (no bound on the angle anywhere): Casimir
    to round-off over 1e5 steps, and the same trajectory as rotations by XLA's cos and sin."""
    step = jaxsplit.splitting(STANDARD, "kahan-li-6", "casimir")
    # angles of ~1e-2 (1e5 steps) and of radians (2e4 steps: the rounding of c² + s² then
    # enters each rotation undamped, 4 sin²(θ/2) δ, and the orbit repeats it: ~1e-17 a step)
    for h, n in ((0.1, 100_000), (2.5, 20_000)):
        run = jaxsplit.integrate(step, M0, h, n, save_every=n // 10)
        c = jnp.sum(run.x**2, axis=1)
        assert float(jnp.max(jnp.abs(c / c[0] - 1))) <= CASIMIR_TOL, h
    reference = M0
    for piece, weight in step.word * 3:  # three steps with XLA's cos and sin, as so3's rotation formula
        flow = step.flows[piece]
        angle = flow.rate * reference[flow.axis] * weight * 2.5
        c_, s_ = jnp.cos(angle), jnp.sin(angle)
        i, j = (flow.axis + 1) % 3, (flow.axis + 2) % 3
        xi, xj = reference[i], reference[j]
        reference = reference.at[i].set(c_ * xi + s_ * xj).at[j].set(c_ * xj - s_ * xi)
    assert float(jnp.max(jnp.abs(jaxsplit.integrate(step, M0, 2.5, 3).final - reference))) <= 1e-14


def _program(fn, *args):
    """The compiled program's text, and its arithmetic: counts of each elementwise op."""
    text = jax.jit(fn).lower(*args).compile().as_text()
    ops = collections.Counter(re.findall(r"= \w+\[[^\]]*\]\S* (\w+)\(", text))
    arithmetic = {k: v for k, v in ops.items() if k in ("multiply", "add", "subtract", "select", "round-nearest-even",
                                                         "clamp", "sine", "cosine", "maximum", "minimum")}
    return text, arithmetic


def _systems():
    heavy = jaxsplit.heavy_top(jnp.array([2.0, 1.6, 1.0]), jnp.array([0.0, 0.0, 0.4]), 1.3)
    gravity = jaxsplit.gravity_gradient(jnp.array([2.0, 1.6, 1.0]), 0.7)
    attitude = jaxsplit.attitude(jnp.array([2.0, 1.6, 1.0]))
    return {"free body": (jaxsplit.splitting(STANDARD, "kahan-li-8", "casimir"), M0),
            "heavy top": (jaxsplit.splitting(heavy, "strang"), (M0, jnp.array([0.1, 0.2, 0.97]))),
            "gravity gradient": (jaxsplit.splitting(gravity, "strang"), (M0, jnp.eye(3)[2])),
            "attitude": (jaxsplit.splitting(attitude, "strang"), (M0, jnp.eye(3)))}


@pytest.mark.parametrize("system", ["free body", "heavy top", "gravity gradient", "attitude"])
def test_transformed_runs_use_the_same_kernels_as_the_direct_call(system):
    """No silent fallback: the program of ``integrate`` under ``jit(vmap(...))`` holds exactly
    the arithmetic of the direct call on the batch (no sine, no cosine, no other kernel), and
    so does its gradient under ``jit(grad(...))`` with the reversible adjoint."""
    step, x0 = _systems()[system]
    batch = jax.tree_util.tree_map(lambda a: jnp.stack([a, a * 0.9]), x0)

    def run(x):
        return jaxsplit.integrate(step, x, 0.05, 7).final

    direct_text, direct = _program(run, batch)
    vmapped_text, vmapped = _program(jax.vmap(run), batch)
    assert "sine" not in direct and "cosine" not in direct
    assert vmapped == direct, (vmapped, direct)
    grad = lambda x: jax.grad(lambda y: jnp.sum(jax.tree_util.tree_leaves(
        jaxsplit.integrate(step, y, 0.05, 7, adjoint="reversible").final)[0] ** 2))(x)
    _, gradient = _program(grad, x0)
    assert "sine" not in gradient and "cosine" not in gradient
    # must fail: XLA's own cos and sin are visible to the same count
    _, plain = _program(lambda a: jnp.cos(a) + jnp.sin(a), jnp.ones(3))
    assert plain.get("cosine") and plain.get("sine")


def test_a_batch_matches_single_states_and_vmap():
    states = jax.random.normal(jax.random.PRNGKey(3), (5, 3))
    step = jaxsplit.splitting(STANDARD, "strang", "casimir")
    batch = jaxsplit.integrate(step, states, 0.05, 200, save_every=50)
    assert batch.x.shape == (5, 5, 3)
    for b in range(5):
        one = jaxsplit.integrate(step, states[b], 0.05, 200, save_every=50).x
        np.testing.assert_allclose(batch.x[:, b], one, atol=ROUNDOFF)
    mapped = jax.jit(jax.vmap(lambda m: jaxsplit.integrate(step, m, 0.05, 200).final))(states)
    np.testing.assert_allclose(mapped, batch.final, atol=ROUNDOFF)



@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_the_kernels_primitives_trace_the_program_the_operators_trace(dtype, monkeypatch):
    """``so3._plain``: the rotation kernel calls lax's primitives where jnp's operators would
    promote nothing (15 % less tracing of a user's program); the program must be the same
    equation for equation, and a weakly typed angle keeps the operators (and its weak type)."""
    phi = jnp.linspace(-7.0, 7.0, 5, dtype=dtype)
    x = jax.random.normal(jax.random.PRNGKey(0), (5, 3), dtype)

    def kernel(phi, x):
        c, s = so3.half_turn(phi)
        return so3._turn_axis(x, 1, c, s)

    fast = str(jax.make_jaxpr(kernel)(phi, x))
    with monkeypatch.context() as m:
        m.setattr(so3, "_plain", lambda *arrays: False)
        assert str(jax.make_jaxpr(kernel)(phi, x)) == fast
    assert so3._plain(phi) and not so3._plain(phi, x)  # different shapes: the operators broadcast
    weak = so3.half_turn(0.5)
    assert all(jax.typeof(v).weak_type for v in weak) and not so3._plain(jnp.asarray(0.5))

def test_the_select_form_is_traced_only_inside_jaxsplits_loops():
    """Rotations use the select form only in the body of ``_loops.threaded`` (whose state XLA
    cannot hoist anything from); elsewhere (a user's own loop, a differentiated run) the stack."""
    from jaxsplit.core import _loops

    seen = []
    assert not _loops.selects()
    _loops.threaded(lambda x, inv: seen.append(_loops.selects()) or x * inv, jnp.ones(3), jnp.asarray(2.0), 3)
    _loops.threaded(lambda x, inv: seen.append(_loops.selects()) or x * inv, jnp.ones(3), jnp.asarray(2.0),
                    jnp.asarray(3))
    assert seen and all(seen) and not _loops.selects()
    # the value and the derivatives are those of the plain loop (reverse mode saves no invariant per step)
    body = lambda x, inv: x * inv[0] + inv[1]
    plain = lambda x, a, b: jax.lax.fori_loop(0, 5, lambda _, y: body(y, (a, b)), x)
    looped = lambda x, a, b: _loops.repeated(body, x, (a, b), 5)
    args = (jnp.asarray([1.0, 2.0]), jnp.asarray(0.9), jnp.asarray(0.1))
    np.testing.assert_allclose(looped(*args), plain(*args), rtol=ROUNDOFF)
    for k in range(3):
        np.testing.assert_allclose(jax.grad(lambda *a: jnp.sum(looped(*a)), argnums=k)(*args),
                                   jax.grad(lambda *a: jnp.sum(plain(*a)), argnums=k)(*args), rtol=ROUNDOFF)
    tangent = jax.jvp(looped, args, (jnp.ones(2), jnp.asarray(1.0), jnp.asarray(0.0)))[1]
    np.testing.assert_allclose(tangent, jax.jvp(plain, args, (jnp.ones(2), jnp.asarray(1.0), jnp.asarray(0.0)))[1],
                               rtol=ROUNDOFF)


# ------------------------------------------------------------ the kernel chosen inside the program
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_the_short_kernels_are_accurate_to_round_off_within_their_bounds(dtype):
    """Each of ``SHORT_LIMITS``'s polynomials (no reduction) meets the general kernel's accuracy
    on |φ| <= its bound, and has fewer terms than the general kernel."""
    from jaxsplit.core._angles import SHORT_LIMITS, assuming

    general = sum(map(len, so3._kernel_constants(np.dtype(dtype).name)[3:]))
    for limit in SHORT_LIMITS:
        phi = np.random.default_rng(2).uniform(-float(limit), float(limit), 100_001)
        phi[:3] = [float(limit), -float(limit), 0.0]
        with assuming(limit):
            cos_err, sin_err, unit, signs = _errors(phi, dtype)
        assert signs == {1.0} and cos_err <= KERNEL_ULPS and sin_err <= KERNEL_ULPS and unit <= UNIT_CIRCLE_ULPS
        assert sum(map(len, so3._short_polynomials(np.dtype(dtype).name, limit))) < general


def _kernel_of_run(step, x, h):
    """The kernel ``by_angle_bound`` picks for a run of ``step`` from ``x`` with step ``h``:
    the bound it traced the chosen branch under (0: the general kernel)."""
    from jaxsplit.core._angles import by_angle_bound, short_angles

    return by_angle_bound(step, x, h, lambda: jnp.asarray(float(short_angles() or 0)))


def test_a_run_picks_its_kernel_inside_the_program_from_its_largest_angle():
    """The tier follows the largest half angle |rate|·|m|·|weight|·|h|/2, with h traced (under
    jit and under vmap, where it is one choice for the whole batch), and NaN takes the general
    kernel. Flows that bound no angle (a heavy top's kick) always run the general one."""
    from jaxsplit.core._angles import SHORT_LIMITS

    step = jaxsplit.splitting(STANDARD, "kahan-li-8", "casimir")
    unit = float(step.turn_rate(M0)) / 2  # half angle per unit h
    choose = jax.jit(lambda x, h: _kernel_of_run(step, x, h))
    for limit, next_one in zip(SHORT_LIMITS, SHORT_LIMITS[1:] + (0,), strict=True):  # 0: the general kernel
        assert float(choose(M0, 0.99 * float(limit) / unit)) == float(limit)
        assert float(choose(M0, 1.01 * float(limit) / unit)) == float(next_one)
    assert float(choose(M0, jnp.nan)) == 0.0 and float(choose(M0 * jnp.inf, 0.1)) == 0.0
    # one body with a large |m| in a batch moves the whole batch to the general kernel
    small_h = 0.5 * float(SHORT_LIMITS[0]) / unit
    batch = jnp.stack([M0, M0 * 100.0])
    assert float(jax.jit(jax.vmap(choose, (0, None)))(batch[:1], small_h)[0]) == float(SHORT_LIMITS[0])
    assert set(np.asarray(jax.jit(jax.vmap(choose, (0, None)))(batch, small_h)).tolist()) == {0.0}
    heavy = jaxsplit.splitting(jaxsplit.heavy_top(jnp.array([2.0, 1.6, 1.0]), jnp.array([0.0, 0.0, 0.4]), 1.3),
                               "strang")
    assert float(_kernel_of_run(heavy, (M0, jnp.array([0.1, 0.2, 0.97])), 1e-3)) == 0.0


def test_every_kernel_gives_the_general_kernels_run_to_round_off():
    """The same run with each tier's kernel and with the general one alone (no short tier): the
    trajectories agree to round-off, and under vmap the choice is a branch (a ``case``), not a
    select that would run every loop."""
    import jaxsplit.core._angles as angles

    step = jaxsplit.splitting(STANDARD, "kahan-li-8", "casimir")
    unit = float(step.turn_rate(M0)) / 2
    states = jnp.stack([M0, M0 * 0.9, M0[::-1]])
    run = lambda x, h: jaxsplit.integrate(step, x, h, 40).final
    for h in [0.5 * float(limit) / unit for limit in angles.SHORT_LIMITS]:
        tiered = jax.jit(run)(states, h)
        saved = angles.SHORT_LIMITS
        try:
            angles.SHORT_LIMITS = ()
            general = jax.jit(lambda x, h: jaxsplit.integrate(step, x, h, 40).final)(states, h)
        finally:
            angles.SHORT_LIMITS = saved
        assert float(jnp.max(jnp.abs(tiered - general))) <= ROUNDOFF, h
    lowered = jax.jit(jax.vmap(run, (0, None))).lower(states, 0.1).as_text()
    assert "stablehlo.case" in lowered
