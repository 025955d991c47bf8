"""The reversible adjoint beyond the free body: a heavy top (rotations of (m, Γ) and the
gravity kick), fused rotation and kick pullbacks against the generic one, any scheme of
reversible flows. (Free-body agreement over 1e5 steps and flat memory: test_integrate_outputs.)"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.core import _adjoints
from jaxsplit.core._compose import kept_blocks
from jaxsplit.core._flows import split_parameters, sum_to_shape

GRADIENT_RTOL = 1e-8  # reversible vs stored gradient (round-off of the rebuilt states)
FUSED_ROUNDOFF = 1e-14  # fused step_back vs the generic jax.vjp one, per call
NOT_REBUILT = 1e-6  # a non-reversible flow stepped back misses its state by at least this

PARTS = ("momentum", "vector")


def top_step(inertia, chi, weight, scheme="strang"):
    w = 1 / inertia
    rotations = tuple(jaxsplit.AxisRotation(k, w[k], PARTS) for k in range(3))
    return jaxsplit.compose(rotations + (jaxsplit.heavy_top(inertia, chi, weight).kick(),), scheme)


TOP_ARGS = (jnp.array([1.0, 1.2, 0.6]), jnp.array([0.0, 0.05, 0.3]), jnp.asarray(1.5),
            (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97])))


def top_loss(adjoint, n):
    def loss(inertia, chi, weight, x0):
        m, gamma = jaxsplit.integrate(top_step(inertia, chi, weight), x0, 0.01, n, adjoint=adjoint).final
        return jnp.sum(m * jnp.arange(1.0, 4.0)) + jnp.sum(gamma**3)

    return loss


def _relative(a, b):
    return max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y)))
               for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)))


SHORT, LONG = 2_000, 200_000  # steps: the gradients are compared on the short run; memory on both


@pytest.fixture(scope="module")
def top_gradients():
    """{(adjoint, n): the compiled gradient of ``top_loss``} (inertia traced): one compilation
    each, shared by the agreement test (which runs the short ones) and the memory test."""
    return {(a, n): jax.jit(jax.grad(top_loss(a, n), argnums=(0, 1, 2, 3))).lower(*TOP_ARGS).compile()
            for a in ("store", "reversible") for n in (SHORT, LONG)}


def test_heavy_top_like_gradients_match_the_stored_ones(top_gradients):
    grads = {a: top_gradients[a, SHORT](*TOP_ARGS) for a in ("store", "reversible")}
    assert _relative(grads["reversible"], grads["store"]) <= GRADIENT_RTOL
    # must fail: the same comparison sees the gradient of a body whose inertia differs by 1e-4
    other = top_gradients["store", SHORT](TOP_ARGS[0] * (1 + 1e-4), *TOP_ARGS[1:])  # the compiled gradient
    assert _relative(other[0], grads["store"][0]) > GRADIENT_RTOL


def test_heavy_top_like_memory_does_not_grow_with_the_step_count(top_gradients):
    sizes = {key: compiled.memory_analysis().temp_size_in_bytes for key, compiled in top_gradients.items()}
    assert sizes["reversible", LONG] == sizes["reversible", SHORT]
    assert sizes["store", LONG] > 50 * sizes["store", SHORT]
    # "store" keeps one state in KEEP_EVERY: its memory is those states (6 float64 each) and a
    # few KiB; keeping every state would take KEEP_EVERY times as much
    kept = LONG // _adjoints.KEEP_EVERY * 6 * 8
    assert kept < sizes["store", LONG] < kept + 2**14


def _normal(shape, seed):
    return jax.random.normal(jax.random.PRNGKey(seed), shape)


ROTATED = {  # (parts, state, an angle of several radians)
    "m": (None, _normal((3,), 0), False),
    "batch": (None, _normal((4, 3), 1), False),
    "batch, large angles": (None, 10 * _normal((4, 3), 1), True),
    "batch of (m, vector)": (PARTS, (_normal((4, 3), 5), _normal((4, 3), 6)), False),
    "m, vector, attitude, fixed": (("momentum", "vector", "attitude", "fixed"),
                                   (_normal((3,), 2), _normal((3,), 3), _normal((3, 3), 4), jnp.array(2.0)), False),
}


@jax.jit
def _pullbacks(flow, x, t, ct):
    """(the fused ``step_back``, the generic ``jax.vjp`` one) of ``flow``: one compiled program
    (op-by-op dispatch of both cost more than compiling them together). The fused one may leave
    its parameter and time cotangents per state (the caller sums them): summed here as ``retrace`` does."""
    x_before, ct_x, ct_parameters, ct_t = flow.step_back(x, t, ct)
    summed = [None if c is None else sum_to_shape(c, jnp.shape(p)) for c, p in zip(ct_parameters, split_parameters(flow)[0])]
    return (x_before, ct_x, summed, jnp.sum(ct_t)), jaxsplit.AbstractFlow.step_back(flow, x, t, ct)


@pytest.mark.parametrize("case", ROTATED)
def test_fused_rotation_step_back_equals_the_generic_pullback(case):
    parts, x, _ = ROTATED[case]
    rotation = jaxsplit.AxisRotation(1, jnp.asarray(0.7), parts)
    ct = jax.tree_util.tree_map(lambda a: jnp.cos(3 * a), x)
    fused, generic = _pullbacks(rotation, x, 0.3, ct)
    for a, b in zip(jax.tree_util.tree_leaves(fused), jax.tree_util.tree_leaves(generic)):
        np.testing.assert_allclose(a, b, atol=FUSED_ROUNDOFF, rtol=FUSED_ROUNDOFF)
    rebuilt = rotation(fused[0], 0.3)
    for a, b in zip(jax.tree_util.tree_leaves(rebuilt), jax.tree_util.tree_leaves(x)):
        np.testing.assert_allclose(a, b, atol=FUSED_ROUNDOFF)


KICK_STATE = ((_normal((3,), 7), _normal((3,), 8) / jnp.linalg.norm(_normal((3,), 8))),
              (_normal((5, 3), 9), _normal((5, 3), 10) / jnp.linalg.norm(_normal((5, 3), 10), axis=-1, keepdims=True)))
KICKS = {"heavy top": jaxsplit.heavy_top(jnp.array([1.0, 1.2, 0.6]), jnp.array([0.1, 0.05, 0.3]), 1.5).kick(),
         "gravity gradient": jaxsplit.gravity_gradient(jnp.array([2.0, 1.0, 2 / 3]), 0.8, allow_nonphysical=True).kick()}


def _max_difference(a, b):
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)))


@pytest.mark.parametrize("name", KICKS)
@pytest.mark.parametrize("batch", (0, 1))
def test_fused_kick_step_back_equals_the_generic_pullback(name, batch):
    kick, x = KICKS[name], KICK_STATE[batch]
    ct = jax.tree_util.tree_map(lambda a: jnp.cos(3 * a), x)
    fused, generic = _pullbacks(kick, x, 0.3, ct)
    assert _max_difference(fused, generic) <= FUSED_ROUNDOFF
    assert _max_difference(kick(fused[0], 0.3), x) <= FUSED_ROUNDOFF
    # must fail: the same comparison sees a pullback at a step 1e-6 longer (the same compiled program)
    assert _max_difference(_pullbacks(kick, x, 0.3 * (1 + 1e-6), ct)[0], generic) > FUSED_ROUNDOFF


def test_a_kick_whose_velocity_moves_along_it_is_not_stepped_back():
    """Why the velocity must be constant along the kick: x ← x + t·m reads the part it moves."""
    class Drift(jaxsplit.AbstractKick):
        def velocity(self, x):
            return x[0], None

    x = KICK_STATE[0]
    before = Drift().step_back(x, 0.3, x)[0]
    assert _max_difference(Drift()(before, 0.3), x) > NOT_REBUILT


def test_a_non_reversible_flow_does_not_rebuild_its_state():
    """Why only reversible flows are accepted: stepping back through x ↦ x + t x² misses."""
    flow = jaxsplit.FunctionFlow(lambda x, t: x + t * x**2, group=False)
    x = jnp.array([0.3, -0.5, 0.8])
    before = flow.step_back(x, 0.3, jnp.ones(3))[0]
    assert float(jnp.max(jnp.abs(flow(before, 0.3) - x))) > NOT_REBUILT
    assert not flow.is_reversible and jaxsplit.AxisRotation(0, 1.0).is_reversible


def test_any_scheme_of_reversible_flows_is_stepped_back_sub_flow_by_sub_flow():
    """Lie–Trotter is not time-symmetric, but each rotation is inverted by its own flow."""
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.STANDARD_CASE.inertia), allow_nonphysical=True)
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)

    def loss(adjoint):
        def f(inertia, m):
            step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "lie-trotter", "axes")
            return jnp.sum(jaxsplit.integrate(step, m, 0.01, 2_000, adjoint=adjoint).final * jnp.arange(1.0, 4.0))
        return jax.jit(jax.grad(f, argnums=(0, 1)))

    assert _relative(loss("reversible")(body.inertia, m0), loss("store")(body.inertia, m0)) <= GRADIENT_RTOL


@pytest.mark.parametrize("layout", ["(m, Γ) float64, float32", "(m, counter) float64, int32"])
def test_every_adjoint_takes_a_state_of_mixed_dtypes(layout):
    """A state whose leaves differ in dtype is not carried as one array (the joint layout needs
    one dtype): floating leaves are promoted to the widest before the run, integer ones ride
    along, and every adjoint gives the same gradient."""
    parts = ("momentum", "vector") if "Γ" in layout else ("momentum", "fixed")
    step = jaxsplit.compose([jaxsplit.AxisRotation(k, jnp.asarray(0.5 + k), parts) for k in range(3)], "strang")
    m0 = jnp.array([0.3, 0.5, 0.8])
    other = m0.astype(jnp.float32) if "Γ" in layout else jnp.asarray(3, jnp.int32)

    def loss(adjoint):
        def f(m):
            final = jaxsplit.integrate(step, (m, other), 0.01, 200, adjoint=adjoint).final
            assert final[0].dtype == jnp.float64 and final[1].dtype == (jnp.float64 if "Γ" in layout else jnp.int32)
            return jnp.sum(final[0] * jnp.arange(1.0, 4.0)) + jnp.sum(jnp.asarray(final[1], jnp.float64) ** 2)
        return jax.jit(jax.grad(f))

    stored = loss("store")(m0)
    assert float(jnp.max(jnp.abs(stored))) > 0.1  # must-fail guard
    for adjoint in ("checkpoint", "reversible"):
        assert _relative(loss(adjoint)(m0), stored) <= GRADIENT_RTOL, adjoint


# ------------------------------------------------------------------ the stored adjoint, retraced
STORED_VS_FORWARD = 1e-10  # stored (walked back from every 16th state) vs forward-mode, 500 steps
KEPT_ROUNDOFF = 1e-13  # walked back from every k-th kept state vs from every state (round-off of < 2k steps)
RETRACED_STEPS = 500  # a count no other test compiles (``_retraced`` must trace afresh)


def _retraced(fn, *args) -> bool:
    """Whether tracing ``fn`` runs the stored adjoint's own backward pass (a custom VJP). Call it
    before ``fn``'s run is compiled otherwise: integrate's own jit would reuse that trace."""
    from unittest import mock

    from jaxsplit.core import _adjoints
    with mock.patch.object(_adjoints, "advance_stored_retraced", wraps=_adjoints.advance_stored_retraced) as spy:
        jax.make_jaxpr(fn)(*args)
    return spy.called


def test_the_stored_gradient_walks_back_from_kept_states_and_matches_forward_mode():
    """Under reverse mode, "store" keeps one state in ``KEEP_EVERY`` and walks the steps back
    from each with the flows' fused pullbacks; forward mode (jacfwd, its own differentiated scan) is an
    independent reference, and a hessian (forward over reverse) goes through it."""
    loss = top_loss("store", RETRACED_STEPS)
    assert _retraced(jax.grad(loss), *TOP_ARGS) and not _retraced(jax.jacfwd(loss), *TOP_ARGS)
    reverse = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))(*TOP_ARGS)
    forward = jax.jit(jax.jacfwd(loss, argnums=(0, 1, 2, 3)))(*TOP_ARGS)
    assert _relative(reverse, forward) <= STORED_VS_FORWARD
    # must fail: the comparison sees a gradient at an inertia 1e-6 away
    other = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))(TOP_ARGS[0] * (1 + 1e-6), *TOP_ARGS[1:])
    assert _relative(other[0], forward[0]) > STORED_VS_FORWARD
    def free(inertia):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1)
        return jnp.sum(jaxsplit.integrate(step, jnp.array([0.6, 0.1, 0.8]), 0.05, 20).final ** 3)

    inertia = jnp.array([2.0, 1.0, 2 / 3])
    np.testing.assert_allclose(jax.hessian(free)(inertia), jax.jacfwd(jax.jacfwd(free))(inertia), rtol=1e-10, atol=1e-12)


# (steps, keep every k): blocks of 17 (k = 16 does not divide 170), blocks of 7 after a rest of 2
# steps, one block (k > n), every state (k = 1)
KEPT_CASES = ((170, 1), (170, 16), (170, 7), (12, 1), (12, 16))


@jax.jit
def _kept_walks(x0, ct, inertia):
    """{"n, k": (final state, kept states, retrace's (x0, ct_x0, ct_parameters, ct_h))} of ``advance(...,
    keep=k)`` and ``retrace(..., kept=)`` for each (n, k) of ``KEPT_CASES``; and "one step off": the
    walk of (170, 7) restarted from the states one step before the kept ones. One compiled program."""
    step = top_step(inertia, TOP_ARGS[1], TOP_ARGS[2])
    out = {}
    for n, every in KEPT_CASES:
        y, kept = step.advance(x0, 0.01, n, keep=every)
        out[f"{n}, {every}"] = y, kept, step.retrace(y, 0.01, n, ct, kept=kept)
    y, _, _ = out["170, 7"]
    blocks, per_block, rest = kept_blocks(170, 170 // 7)
    off = jax.tree_util.tree_map(lambda a: a[np.arange(blocks) * per_block + rest + per_block - 2], out["170, 1"][1])
    out["one step off"] = step.retrace(y, 0.01, 170, ct, kept=off)
    return out


def test_walking_back_from_every_kth_kept_state_equals_walking_back_from_every_state():
    """``advance(..., keep=k)`` keeps ⌊n/k⌋ states (``kept_blocks``: the rest steps first, then
    blocks of ⌊n/blocks⌋ steps, each block's end kept), the same states as ``keep=1`` keeps at
    those steps; ``retrace`` from them gives the gradient of walking back from every state to
    round-off (the rebuilt states carry it over fewer than 2k steps; gradients through 10^4
    steps of a chaotic top: ``benchmarks/results/gradients.md``)."""
    x0 = (_normal((4, 3), 11), _normal((4, 3), 12))  # 4 tops
    ct = jax.tree_util.tree_map(lambda a: jnp.cos(a) + 2, x0)
    out = _kept_walks(x0, ct, TOP_ARGS[0])
    for n, every in KEPT_CASES:
        y, kept, walked = out[f"{n}, {every}"]
        y1, kept1, walked1 = out[f"{n}, 1"]
        blocks, per_block, rest = kept_blocks(n, max(1, n // every))
        assert kept[0].shape[0] == blocks == max(1, n // every) and rest < every and blocks * per_block + rest == n
        at = np.arange(blocks) * per_block + rest + per_block - 1  # the steps whose states keep=k keeps
        assert _relative(jax.tree_util.tree_map(lambda a, at=at: a[at], kept1), kept) <= KEPT_ROUNDOFF, (n, every)
        assert _relative(y, y1) <= KEPT_ROUNDOFF
        assert _relative(walked, walked1) <= KEPT_ROUNDOFF, (n, every)
    # must fail: the comparison sees a walk restarted from states one step before the kept ones
    assert _relative(out["one step off"], out["170, 1"][2]) > KEPT_ROUNDOFF


def test_the_stored_adjoint_is_retraced_under_a_vmap_inside_grad_and_only_for_reversible_flows():
    inertia = jnp.array([2.0, 1.0, 2 / 3])
    states = jnp.array([[0.6, 0.1, 0.8], [0.2, -0.5, 0.7]])

    def batch_loss(inertia, method="casimir"):
        step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", method, shift=1) if method else \
            jaxsplit.compose([jaxsplit.AxisRotation(0, 1 / inertia[0]), jaxsplit.FunctionFlow(lambda m, t: m * (1 + t), group=False)],
                             "strang")
        run = jax.vmap(lambda m: jaxsplit.integrate(step, m, 0.01, 50).final)
        return jnp.sum(run(states) ** 3)

    assert _retraced(jax.grad(batch_loss), inertia)
    assert not _retraced(jax.grad(lambda i: batch_loss(i, None)), inertia)  # a flow that is no group
    np.testing.assert_allclose(jax.grad(batch_loss)(inertia), jax.jacfwd(batch_loss)(inertia), rtol=1e-11)


def test_a_loop_returning_an_unchanged_part_inside_another_loop_differentiates_with_every_adjoint():
    """A "fixed" part (no flow changes it) in a user's lax.scan under jit(grad): XLA's one-kernel
    emitter aborted the process on such a loop, so it runs as plain loops; run in a child
    process, so an abort fails this test instead of ending the suite."""
    import subprocess
    import sys
    code = """
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import jaxsplit
step = jaxsplit.compose([jaxsplit.AxisRotation(k, jnp.asarray(0.5 + k), ("momentum", "fixed")) for k in range(3)], "strang")
def f(m, adjoint):
    x = jax.lax.scan(lambda x, _: (jaxsplit.integrate(step, x, 0.01, 10, adjoint=adjoint).final, None),
                     (m, jnp.ones(3)), length=20)[0]
    return jnp.sum(x[0] ** 3)
m = jnp.array([0.3, 0.5, 0.8])
reference = jax.jacfwd(f)(m, "store")
for adjoint in ("store", "checkpoint", "reversible"):
    assert float(jnp.max(jnp.abs(jax.jit(jax.grad(f), static_argnums=1)(m, adjoint) - reference))) < 1e-12, adjoint
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
