"""The rotation kernel: polynomial cos/sin where the Casimir bounds every angle of a run,
the general path elsewhere, chosen once per run and visible; batches components-first."""

import dataclasses
import gc
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.systems import so3

KERNEL_ULPS = 2  # polynomial cos, sin vs NumPy's on |θ| <= each limit, in units of eps
UNIT_CIRCLE_ULPS = 4  # cos² + sin² − 1
BEYOND_LIMIT_ULPS = 100  # cos² + sin² − 1 at 3× the limit exceeds this (float64): the limit matters
CASIMIR_TOL = 1e-12  # relative, 1e5 steps
PATHS_AGREE = 1e-8  # polynomial vs general kernel after 1e5 steps (round-off grows apart)
ROUNDOFF = 1e-13

STANDARD = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia))
M0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)


@pytest.mark.parametrize("limit", so3.POLYNOMIAL_LIMITS)
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_polynomial_kernel_is_accurate_to_round_off_within_its_limit(dtype, limit):
    theta = jnp.linspace(-limit, limit, 20001, dtype=dtype)
    c, s = (np.asarray(a, np.float64) for a in so3.cos_sin(theta, "polynomial", limit))
    exact = np.asarray(theta, np.float64)
    eps = float(jnp.finfo(dtype).eps)
    assert c.dtype == s.dtype and so3.cos_sin(theta, "polynomial", limit)[0].dtype == dtype
    assert np.max(np.abs(c - np.cos(exact))) <= KERNEL_ULPS * eps
    assert np.max(np.abs(s - np.sin(exact))) <= KERNEL_ULPS * eps
    assert np.max(np.abs(c * c + s * s - 1)) <= UNIT_CIRCLE_ULPS * eps
    # must fail: beyond its limit the truncated series is no longer a rotation to round-off
    far = jnp.asarray([3 * limit], dtype=jnp.float64)
    cf, sf = so3.cos_sin(far, "polynomial", limit)
    assert abs(float(cf[0] ** 2 + sf[0] ** 2) - 1) > BEYOND_LIMIT_ULPS * float(jnp.finfo(jnp.float64).eps)


def test_the_run_picks_the_kernel_from_the_casimir_bound():
    step = jaxsplit.splitting(STANDARD, "kahan-li-6", "casimir")
    assert step.kernel == "general"  # as built
    fast = step.for_run(M0, 0.1)  # |c| |m0| reach h = 0.5 · 1 · 0.8 · 0.1
    assert fast.kernel == "polynomial" and "kernel='polynomial'" in repr(fast)
    assert step.for_run(M0, 10.0).kernel == "general"  # angles up to ~4 rad: the general path
    # the truncation covers the run's bound, and smaller steps get fewer terms
    m_norm = float(jnp.linalg.norm(M0))
    for h in (0.01, 0.1, 1.0):
        run = step.for_run(M0, h)
        for flow, reach in zip(run.flows, step.reach()):
            assert flow.angle_limit >= abs(float(flow.rate)) * m_norm * reach * h
    terms = [len(so3._polynomials("float64", step.for_run(M0, h).flows[0].angle_limit)[0]) for h in (0.01, 1.0)]
    assert terms[0] < terms[1]
    assert jaxsplit.integrate(step, M0, 0.1, 10).kernel == "polynomial"
    assert jaxsplit.integrate(step, M0, 10.0, 10).kernel == "general"
    # under the caller's jit the values are traced: the general path (specialise beforehand
    # with step.for_run to keep the polynomial one)
    assert jax.jit(lambda m: jaxsplit.integrate(step, m, 0.1, 3))(M0).kernel == "general"
    assert jax.jit(lambda m: jaxsplit.integrate(fast, m, 0.1, 3))(M0).kernel == "polynomial"
    # a flow that changes |m| leaves no bound: every flow stays general
    kick = jaxsplit.FunctionFlow(lambda m, t: m * (1 + t))
    assert jaxsplit.compose(STANDARD.split("casimir") + (kick,), "strang").for_run(M0, 0.1).kernel == "general"



def test_a_runs_preparation_is_remembered_per_step_and_choice_and_goes_with_the_step():
    """``for_run`` builds each choice once per step object (a loop of ``integrate`` calls does not
    rebuild the prepared flows), a changed choice gets its own prepared step, and the memo
    neither outlives the step nor grows past ``KEPT`` choices."""
    from jaxsplit.core import _memo

    step = jaxsplit.splitting(STANDARD, "kahan-li-6", "casimir")
    small = step.for_run(M0, 0.1)
    assert step.for_run(M0, 0.1) is small and small.for_run(M0, 0.1) is small
    large = step.for_run(M0, 1.0)  # angles ~10x: a longer polynomial
    assert large is not small and large.flows[0].angle_limit > small.flows[0].angle_limit
    assert step.for_run(M0, 0.1) is small  # the first choice is still its own
    for k in range(2 * _memo.KEPT):  # many distinct choices (bounds) on a fresh step
        step.for_run(M0 * (1 + k), 0.1)
    assert len(_memo._BY_OWNER[id(step)][1]) <= _memo.KEPT
    before = _memo.remembered()
    del step, small, large
    gc.collect()
    assert _memo.remembered() < before


def test_the_bound_is_reduced_where_the_batch_lives():
    """The run's max|m| by NumPy on the CPU and by one device reduction on an accelerator: the
    same value (to round-off) on any batch, so both choose the same kernel and truncation."""
    batch = np.random.default_rng(3).standard_normal((4, 5, 3)) * np.array([1.0, 3.0, 0.5])
    host = so3._largest_norm(jnp.asarray(batch))
    device = float(so3._device_largest_norm(jnp.asarray(batch)))
    assert host == pytest.approx(np.max(np.linalg.norm(batch, axis=-1)), rel=ROUNDOFF)
    assert device == pytest.approx(host, rel=ROUNDOFF)
    assert so3._largest_norm(batch) == host  # a NumPy batch: read in place
def test_the_polynomial_path_has_no_sine_or_cosine():
    step = jaxsplit.splitting(STANDARD, "strang", "casimir")

    def hlo(s):
        return jax.jit(lambda m: jaxsplit.integrate(s, m, 0.1, 5).final).lower(M0).as_text()

    assert "sine" in hlo(step) and "cosine" in hlo(step)
    fast = hlo(step.for_run(M0, 0.1))
    assert "sine" not in fast and "cosine" not in fast


def test_structure_and_accuracy_are_those_of_the_general_path():
    """Casimir to round-off over 1e5 steps on the polynomial path; the same trajectory as the
    general path up to round-off growth."""
    step = jaxsplit.splitting(STANDARD, "kahan-li-6", "casimir")
    fast = jaxsplit.integrate(step, M0, 0.1, 100_000, save_every=10_000)
    assert fast.kernel == "polynomial"
    general = jax.jit(lambda m: jaxsplit.integrate(step, m, 0.1, 100_000, save_every=10_000).x)(M0)
    c = jnp.sum(fast.x**2, axis=1)
    assert float(jnp.max(jnp.abs(c / c[0] - 1))) <= CASIMIR_TOL
    assert float(jnp.max(jnp.abs(fast.x - general))) <= PATHS_AGREE
    # the order ladders of the checks run the polynomial kernel where the bound allows
    order = jaxsplit.estimate_order(jaxsplit.splitting(STANDARD, "strang", "casimir"), M0, 10.0,
                                    jaxsplit.ladder(200), jnp.asarray(jaxsplit.STANDARD_CASE.reference))
    assert abs(order.order - 2) <= 0.3


def test_a_batch_runs_components_first_and_matches_single_states():
    states = jax.random.normal(jax.random.PRNGKey(3), (5, 3))
    step = jaxsplit.splitting(STANDARD, "strang", "casimir")
    fast = step.for_run(states, 0.05)
    assert fast.structure_of_arrays and fast.kernel == "polynomial"
    assert not step.for_run(M0, 0.05).structure_of_arrays  # one state: nothing to lay out
    batch = jaxsplit.integrate(step, states, 0.05, 200, save_every=50)
    assert batch.x.shape == (5, 5, 3)
    for b in range(5):
        one = jaxsplit.integrate(step, states[b], 0.05, 200, save_every=50).x
        np.testing.assert_allclose(batch.x[:, b], one, atol=ROUNDOFF)
    # jax.vmap of the step keeps working (the general path, inside vmap)
    mapped = jax.vmap(lambda m: jaxsplit.integrate(step, m, 0.05, 200).final)(states)
    np.testing.assert_allclose(mapped, batch.final, atol=ROUNDOFF)
    # and the one-step call of a components-first composition takes (..., 3) states
    np.testing.assert_allclose(fast(states, 0.05), step(states, 0.05), atol=ROUNDOFF)


@pytest.mark.parametrize("scheme, h, last", [("strang", 0.05, False),           # two rotations: first
                                              ("kahan-li-8", 0.5, True),          # angles <= 1/4: last
                                              ("kahan-li-8", 1.0, False)])        # larger angles: first
def test_a_batch_layout_follows_the_step_and_both_layouts_agree_bit_for_bit(monkeypatch, scheme, h, last):
    """``for_run`` lays a batch out components last (the select form) only for steps of more
    than two rotations whose angles are bounded by 1/4; either layout gives the same bits."""
    states = jax.random.normal(jax.random.PRNGKey(4), (7, 3))
    states = states / jnp.linalg.norm(states, axis=1, keepdims=True)
    step = jaxsplit.splitting(STANDARD, scheme, "casimir")
    assert step.for_run(states, h).structure_of_arrays != last
    assert not step.for_run(states[0], h).structure_of_arrays  # one state: components last, always
    runs = {}
    for layout, limits in {"first": (10**9, 0.0), "last": (0, math.inf)}.items():
        monkeypatch.setattr(so3, "COMPONENTS_FIRST_UP_TO", limits[0])
        monkeypatch.setattr(so3, "COMPONENTS_LAST_UP_TO", limits[1])
        assert step.for_run(states, h).structure_of_arrays == (layout == "first")
        runs[layout] = np.asarray(jaxsplit.integrate(step, states, h, 30, save_every=10).x)
    np.testing.assert_array_equal(runs["first"], runs["last"])


def test_each_entry_of_a_word_gets_the_polynomial_of_its_own_bound():
    """``for_run`` truncates the polynomial per word entry (``lower_limits``, ``for_weight``):
    each entry's limit covers its own angle bound |rate|·max|m0|·|weight|·h, is never above the
    run's, and the run agrees with one at the run's limit everywhere to round-off."""
    states = jax.random.normal(jax.random.PRNGKey(5), (7, 3))
    states = states / jnp.linalg.norm(states, axis=1, keepdims=True)
    h = 0.5
    step = jaxsplit.splitting(STANDARD, "blanes-casas-murua-8", "casimir")
    fast = step.for_run(states, h)
    assert any(f.lower_limits for f in fast.flows)  # at h = 0.5 some entries need fewer terms
    largest = float(jnp.max(jnp.linalg.norm(states, axis=1)))
    for piece, weight in step.entries():
        flow = fast.flows[piece]
        own = flow.for_weight(weight)
        assert own.angle_limit <= flow.angle_limit
        assert abs(float(flow.rate)) * largest * abs(weight) * h <= own.angle_limit
    # must fail: the largest weight keeps the run's limit, and a smaller limit would not cover it
    for piece, flow in enumerate(fast.flows):
        top = step.reach()[piece]
        assert flow.for_weight(top) is flow
        smaller = [L for L in so3.POLYNOMIAL_LIMITS if L < flow.angle_limit]
        assert all(abs(float(flow.rate)) * largest * top * h > L for L in smaller)
    uniform = type(fast)(tuple(dataclasses.replace(f, lower_limits=()) for f in fast.flows), fast.word, fast.scheme,
                         fast.fsal, fast.structure_of_arrays, fast.processing)
    np.testing.assert_allclose(fast.advance(states, h, 200), uniform.advance(states, h, 200), atol=ROUNDOFF)


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


def test_a_bad_kernel_name_or_limit_is_refused():
    with pytest.raises(jaxsplit.InputError, match="kernel must be one of"):
        jaxsplit.AxisRotation(0, 1.0, kernel="fast")
    with pytest.raises(jaxsplit.InputError, match="angle_limit must be one of"):
        jaxsplit.AxisRotation(0, 1.0, kernel="polynomial", angle_limit=2.0)


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="reads the fusions of XLA's CPU compiler (on an "
                    "H100 the turning kernels held the cosine again: benchmarks/README.md, 'On an H100')")
def test_a_batch_of_general_angles_is_xla_cos_and_sin_bit_for_bit_evaluated_once():
    """The exact reduction that keeps XLA's CPU compiler from re-evaluating cos and sin per
    element written changes no bit (−0.0 and NaN included) and leaves one cos and one sin per
    angle."""
    theta = jnp.array([0.3, -0.0, 0.0, 2.5, -7.0, jnp.nan, jnp.inf])
    once = jax.jit(so3.cos_sin)(theta)
    plain = jax.jit(lambda a: (jnp.cos(a), jnp.sin(a)))(theta)
    for a, b in zip(once, plain):
        np.testing.assert_array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))

    def turned(angle):  # a rotation of 4 stacked vectors: 8 elements written per angle
        return so3._turn_axis(jnp.ones((4,) + angle.shape + (3,)), 2, *so3.half_cos_sin(angle))

    def cosines_in_turning_kernels(fn, angle):  # kernels that write the (4, B, 3) result
        kernels = jax.jit(fn).lower(angle).compile().as_text().split("\n\n")
        return sum(k.count(" cosine(") for k in kernels if f"f64[4,{angle.shape[0]},3]" in k)

    angle = jnp.linspace(0.1, 0.2, 16)
    assert cosines_in_turning_kernels(turned, angle) == 0
    # must fail: the same count sees cos inside the turning kernel without the reduction
    plain = lambda a: so3._turn_axis(jnp.ones((4,) + a.shape + (3,)), 2, jnp.cos(a / 2), jnp.sin(a / 2))
    assert cosines_in_turning_kernels(plain, angle) > 0


@pytest.mark.parametrize("limit", so3.POLYNOMIAL_LIMITS)
def test_the_half_angle_is_truncated_for_half_the_limit_at_full_accuracy(limit):
    theta = jnp.linspace(-limit, limit, 20001)
    c, s = (np.asarray(a) for a in so3.half_cos_sin(theta, "polynomial", limit))
    eps = float(jnp.finfo(jnp.float64).eps)
    assert np.max(np.abs(c - np.cos(np.asarray(theta) / 2))) <= KERNEL_ULPS * eps
    assert np.max(np.abs(s - np.sin(np.asarray(theta) / 2))) <= KERNEL_ULPS * eps
    assert len(so3._polynomials("float64", limit / 2)[0]) < len(so3._polynomials("float64", limit)[0])  # fewer terms
    # must fail: the half-limit truncation used on the full angle is no longer round-off
    cf, sf = (np.asarray(a) for a in so3.cos_sin(jnp.asarray([limit]), "polynomial", limit / 4))
    assert abs(float(cf[0] ** 2 + sf[0] ** 2) - 1) > BEYOND_LIMIT_ULPS * eps


def _taylor_terms(limit: float, offset: int, eps: float) -> int:
    """Terms of the truncated Taylor series of cos (offset 0) or sin/θ (1): up to the first below eps/4 at limit."""
    k = 0
    while limit ** (2 * k) / math.factorial(2 * k + offset) > eps / 4:
        k += 1
    return k


@pytest.mark.parametrize("limit", so3.POLYNOMIAL_LIMITS + tuple(L / 2 for L in so3.POLYNOMIAL_LIMITS))
def test_the_economized_polynomials_are_shorter_than_the_taylor_series(limit):
    """The economization buys its speed with fewer terms (float64: fewer in all at every bound a
    rotation uses, never more for either); the accuracy at those bounds is asserted above."""
    eps = float(jnp.finfo(jnp.float64).eps)
    cos_c, sin_c = so3._polynomials("float64", limit)
    taylor = _taylor_terms(limit, 0, eps), _taylor_terms(limit, 1, eps)
    assert len(cos_c) <= taylor[0] and len(sin_c) <= taylor[1]
    assert len(cos_c) + len(sin_c) < sum(taylor)
    assert cos_c[0] == 1.0 and sin_c[0] == 1.0  # exact at θ = 0: cos 0 = 1, sin θ ~ θ
