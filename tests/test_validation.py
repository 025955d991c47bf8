"""The Python API refuses what the command line refuses (issue 31, section 3): one validation
layer for both. Each class of bad input is tested over its members, not only the instance the
review found: every batchable parameter of every system, every constructor of a body, every
state part with a constraint, every size a user controls. Cheap: refusals happen before any
compilation (shape refusals while tracing); the few runs are a handful of steps.
"""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit import InputError, integrate, splitting

PHYSICAL = jnp.array([2.0, 1.5, 1.0])  # I1 + I2 >= I3 and permutations
SYMMETRIC = jnp.array([2.0, 2.0, 1.0])  # I1 = I2: the potential systems' symmetric split
CHI = jnp.array([0.0, 0.0, 0.5])
M0 = jnp.array([0.6, 0.0, 0.8])
GAMMA0 = jnp.array([0.0, 0.6, 0.8])


def _refused(fn, *words):
    with pytest.raises(InputError) as err:
        fn()
    message = str(err.value)
    assert "\n" not in message, message
    for word in words:
        assert word in message, f"{word!r} missing from {message!r}"
    return message


# ---------------------------------------------------------------- a batched parameter needs a batch of states
TWO = jnp.array([1.0, 2.0])
BATCHED = {  # system with one parameter batched (two values), the state of one body
    "rigid-body inertia": (lambda: jaxsplit.RigidBody(jnp.stack([PHYSICAL, SYMMETRIC])), M0),
    "attitude inertia": (lambda: jaxsplit.attitude(jnp.stack([PHYSICAL, SYMMETRIC])), (M0, jnp.eye(3))),
    "heavy-top inertia": (lambda: jaxsplit.heavy_top(jnp.stack([PHYSICAL, SYMMETRIC]), CHI, 1.0), (M0, GAMMA0)),
    "heavy-top center_of_mass": (lambda: jaxsplit.heavy_top(SYMMETRIC, jnp.stack([CHI, 2 * CHI]), 1.0), (M0, GAMMA0)),
    "heavy-top weight": (lambda: jaxsplit.heavy_top(SYMMETRIC, CHI, TWO), (M0, GAMMA0)),
    "gravity-gradient inertia": (lambda: jaxsplit.gravity_gradient(jnp.stack([PHYSICAL, SYMMETRIC]), 1.0),
                                 (M0, GAMMA0)),
    "gravity-gradient rate": (lambda: jaxsplit.gravity_gradient(SYMMETRIC, TWO), (M0, GAMMA0)),
}


@pytest.mark.parametrize("name", list(BATCHED))
def test_every_batched_parameter_with_one_state_is_refused_in_every_split(name):
    build, x0 = BATCHED[name]
    system = build()
    for split in system.splits():
        if split == "symmetric" and system.inertia.ndim > 1:
            continue  # the symmetric split refuses the asymmetric body of the batch first
        options = {"shift": 1} if split in ("casimir", "spin") else {}
        step = splitting(system, "strang", split, **options)
        _refused(lambda step=step: integrate(step, x0, 0.1, 2).final, "batch shape (2,)", "state's batch shape is ()")


def test_a_batched_parameter_is_refused_under_jit_too_and_one_state_per_value_runs():
    def run(weight, x0):
        return integrate(splitting(jaxsplit.heavy_top(SYMMETRIC, CHI, weight), "strang"), x0, 0.1, 2).final

    _refused(lambda: jax.jit(run)(TWO, (M0, GAMMA0)), "batch shape (2,)")
    states = (jnp.stack([M0, M0]), jnp.stack([GAMMA0, GAMMA0]))
    batched = run(TWO, states)[0]
    one = [run(w, (M0, GAMMA0))[0] for w in (1.0, 2.0)]
    np.testing.assert_allclose(batched, jnp.stack(one), rtol=0, atol=1e-15)  # each state with its own weight


@pytest.mark.parametrize("build", [
    lambda: jaxsplit.heavy_top(jnp.stack([PHYSICAL] * 2), jnp.stack([CHI] * 3), 1.0),
    lambda: jaxsplit.heavy_top(PHYSICAL, jnp.stack([CHI] * 2), jnp.ones(3)),
    lambda: jaxsplit.gravity_gradient(jnp.stack([PHYSICAL] * 2), jnp.ones(3)),
], ids=["inertia-vs-chi", "chi-vs-weight", "inertia-vs-rate"])
def test_parameter_batches_that_do_not_broadcast_are_refused_when_built(build):
    _refused(build, "batch shapes do not broadcast")


# ---------------------------------------------------------------- non-physical bodies: refused unless flagged
CONSTRUCTORS = {
    "RigidBody": lambda i, **kw: jaxsplit.RigidBody(i, **kw),
    "rigid_body": lambda i, **kw: jaxsplit.systems.rigid_body(i, **kw),
    "attitude": lambda i, **kw: jaxsplit.attitude(i, **kw),
    "attitude-quaternion": lambda i, **kw: jaxsplit.attitude(i, quaternion=True, **kw),
    "heavy_top": lambda i, **kw: jaxsplit.heavy_top(i, CHI, 1.0, **kw),
    "gravity_gradient": lambda i, **kw: jaxsplit.gravity_gradient(i, 1.0, **kw),
}
NONPHYSICAL = [([1.0, 1.0, 5.0], "I1 + I2 >= I3"), ([5.0, 1.0, 1.0], "I2 + I3 >= I1"),
               ([1.0, 5.0, 1.0], "I3 + I1 >= I2")]


@pytest.mark.parametrize("name", list(CONSTRUCTORS))
@pytest.mark.parametrize("inertia,failing", NONPHYSICAL)
def test_every_body_constructor_refuses_a_non_physical_body_unless_allowed(name, inertia, failing):
    build = CONSTRUCTORS[name]
    shown = ",".join(f"{v:g}" for v in inertia)
    for kwargs in ({}, {"allow_nonphysical": False}):  # refused by default, as by the CLI
        _refused(lambda kwargs=kwargs: build(inertia, **kwargs), f"inertia {shown} is not a physical body", failing,
                 "allow_nonphysical=True")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # allowed: no warning either
        assert np.allclose(build(inertia, allow_nonphysical=True).inertia, inertia)
        build(PHYSICAL)  # a physical body: no warning, no refusal


BARE_MOMENTS = {  # functions taking bare moments (no flag of their own): a built body is the way
    "splitting": lambda i: jaxsplit.splitting(i, "strang"),
    "exact_solution": lambda i: jaxsplit.exact_solution(i, M0, 1.0),
    "symmetric_solution": lambda i: jaxsplit.symmetric_solution(i, M0, 1.0),
    "rigid_body_system": lambda i: jaxsplit.rigid_body_system(i),
}


@pytest.mark.parametrize("name", list(BARE_MOMENTS))
def test_functions_taking_bare_moments_refuse_a_non_physical_body_and_name_the_built_body(name):
    _refused(lambda: BARE_MOMENTS[name](jnp.array([1.0, 1.0, 5.0])), "inertia 1,1,5 is not a physical body",
             "RigidBody(inertia, allow_nonphysical=True)")
    BARE_MOMENTS[name](jaxsplit.RigidBody(jnp.array([1.0, 1.0, 5.0]), allow_nonphysical=True))  # built: accepted


CASE_FUNCTIONS = {  # the default family (RigidBody) of the explore functions takes the flag too
    "sweep": lambda i, **kw: jaxsplit.sweep("strang", {"m0": M0[None], "inertia": i[None], "h": np.array([0.5])},
                                            t_end=1.0, **kw),
    "reference_solution": lambda i, **kw: jaxsplit.reference_solution(M0[None], i[None], 0.5, **kw),
    "stability_map": lambda i, **kw: jaxsplit.stability_map("strang", [0.1], i[None], **kw),
    "tune_scheme": lambda i, **kw: jaxsplit.tune_scheme(i[None], M0[None], t_end=0.5, n_steps=2, iterations=0,
                                                        scan_points=0, **kw),
}


@pytest.mark.parametrize("name", list(CASE_FUNCTIONS))
def test_the_explore_functions_refuse_non_physical_cases_unless_allowed(name):
    inertia = jnp.array([1.0, 1.0, 5.0])
    _refused(lambda: CASE_FUNCTIONS[name](inertia), "inertia 1,1,5 is not a physical body", "allow_nonphysical=True")
    if name in ("reference_solution", "tune_scheme"):  # cheap to run; a sweep and a map compile (test_sweep, ...)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            CASE_FUNCTIONS[name](inertia, allow_nonphysical=True)


def test_the_standard_case_is_non_physical_and_built_by_its_body_method():
    """(2, 1, 2/3) is the literature's body, not a physical one: bare, it is refused; ``body()``
    passes the flag in one documented place."""
    case = jaxsplit.STANDARD_CASE
    _refused(lambda: jaxsplit.RigidBody(case.inertia), "inertia 2,1,0.666667 is not a physical body",
             "I2 + I3 >= I1", "allow_nonphysical=True")
    assert case.body().inertia.tolist() == list(case.inertia)
    assert case.body(jnp.float32).inertia.dtype == jnp.float32
    assert "allow_nonphysical=True" in type(case).__doc__


def test_the_flag_is_a_bool_and_a_batch_names_its_body():
    for value in ("yes", None, jnp.array(True)):  # None was the warning default: no third mode
        _refused(lambda value=value: jaxsplit.RigidBody(PHYSICAL, allow_nonphysical=value), "allow_nonphysical",
                 "True or False")
    _refused(lambda: jaxsplit.RigidBody(jnp.stack([PHYSICAL, jnp.array([1.0, 1.0, 3.0])]), allow_nonphysical=False),
             "body 1 of the batch", "I1 + I2 >= I3")


def test_moments_whose_inverse_overflows_are_refused_in_their_dtype():
    _refused(lambda: jaxsplit.RigidBody(jnp.array([1e-320, 1.0, 1.0])), "1/I1 overflows", "float64")
    _refused(lambda: jaxsplit.RigidBody(np.array([1.0, 1e-39, 1.0], np.float32), allow_nonphysical=True),
             "1/I2 overflows", "float32")


def test_the_command_line_uses_the_library_check():
    """One check: the CLI's body() is the library's check_moments with the CLI's names."""
    from jaxsplit.cli._problem import body

    _refused(lambda: body((1.0, 1.0, 3.0), False), "--inertia 1,1,3 is not a physical body", "--allow-nonphysical")
    assert body((1.0, 1.0, 3.0), True).inertia.tolist() == [1.0, 1.0, 3.0]


def test_sweep_cases_apply_the_same_policy_to_a_grid_of_ratios():
    _refused(lambda: jaxsplit.sweep_cases(states=1, ratios=[(1.0, 3.0)]), "the ratios' body I 1,1,3",
             "not a physical body", "physical_only=False")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert jaxsplit.sweep_cases(states=1, ratios=[(1.0, 3.0)], physical_only=False)["inertia"].tolist() == [
            [1.0, 1.0, 3.0]]


# ---------------------------------------------------------------- a state off its manifold
ATTITUDE = jaxsplit.attitude(PHYSICAL)
QUATERNION = jaxsplit.attitude(PHYSICAL, quaternion=True)
TOP = jaxsplit.heavy_top(SYMMETRIC, CHI, 1.0)
SATELLITE = jaxsplit.gravity_gradient(SYMMETRIC, 1.0)
REFLECTION = jnp.diag(jnp.array([1.0, 1.0, -1.0]))


@pytest.mark.parametrize("system,split,x0,words", [
    (ATTITUDE, "axes", (M0, 2 * jnp.eye(3)), ["Q must be orthogonal"]),
    (ATTITUDE, "spin", (M0, 2 * jnp.eye(3)), ["Q must be orthogonal"]),
    (ATTITUDE, "axes", (M0, REFLECTION), ["Q must be a rotation", "det Q"]),
    (ATTITUDE, "axes", (M0, jnp.full((3, 3), jnp.nan)), ["finite"]),
    (QUATERNION, "axes", (M0, jnp.array([2.0, 0.0, 0.0, 0.0])), ["unit quaternion", "|q|", "2.0"]),
    (QUATERNION, "spin", (M0, jnp.array([0.5, 0.0, 0.0, 0.0])), ["unit quaternion"]),
    (TOP, "axes", (M0, 2 * GAMMA0), ["Γ must be a unit vector", "2.0"]),
    (TOP, "symmetric", (M0, 2 * GAMMA0), ["Γ must be a unit vector"]),
    (SATELLITE, "axes", (M0, 0.5 * GAMMA0), ["Γ must be a unit vector"]),
], ids=["Q=2I", "Q=2I-spin", "reflection", "Q-nan", "|q|=2", "|q|=0.5-spin", "|Γ|=2", "|Γ|=2-symmetric",
        "satellite-|Γ|=0.5"])
def test_integrate_refuses_an_initial_state_off_its_manifold(system, split, x0, words):
    options = {"shift": 1} if split == "spin" else {}
    _refused(lambda: integrate(splitting(system, "strang", split, **options), x0, 0.1, 2).final, *words)


def test_a_state_on_its_manifold_to_round_off_passes():
    """|Γ|, QᵀQ are Casimirs: a state from a long run (off by round-off) must be accepted."""
    near = GAMMA0 * (1 + 1e-13)
    assert integrate(splitting(TOP, "strang"), (M0, near), 0.1, 2).status == "ok"
    q = jaxsplit.rotation_matrix(2, 0.3) * (1 + 1e-13)
    assert integrate(splitting(ATTITUDE, "strang"), (M0, q), 0.1, 2).status == "ok"


# ---------------------------------------------------------------- times and step sizes
STEP = splitting(jaxsplit.RigidBody(PHYSICAL), "strang")


@pytest.mark.parametrize("t0,words", [
    (math.nan, ["t0", "finite", "nan"]), (math.inf, ["t0", "finite", "inf"]), (-math.inf, ["t0", "finite"]),
    (jnp.array(jnp.nan), ["t0", "finite"]), (1j, ["t0", "real"]), ("0", ["t0", "real"]), (None, ["t0"]),
    (jnp.zeros(2), ["t0", "scalar"]),
], ids=["nan", "inf", "-inf", "nan-array", "complex", "str", "None", "vector"])
def test_integrate_refuses_a_bad_initial_time_for_both_kinds_of_run(t0, words):
    _refused(lambda: integrate(STEP, M0, 0.1, 2, t0=t0).final, *words)
    _refused(lambda: integrate(STEP, M0, 0.1, ts=[0.5], t0=t0).final, *words)


def test_integrate_refuses_a_zero_step_and_complex_output_times():
    for h in (0, 0.0, -0.0, jnp.array(0.0)):
        _refused(lambda h=h: integrate(STEP, M0, h, 2).final, "h must be a non-zero step size")
        _refused(lambda h=h: integrate(STEP, M0, h, ts=[0.5]).final, "h must be a non-zero step size")
    _refused(lambda: integrate(STEP, M0, 0.1, ts=jnp.array([0.5 + 1j, 1.0])).final, "ts must be real times",
             "complex128")
    _refused(lambda: integrate(STEP, M0, 0.1, ts=np.array(["a"])).final, "ts must be real output times")


@pytest.mark.parametrize("check", [
    lambda h: jaxsplit.poisson_defect(STEP, jaxsplit.RigidBody(PHYSICAL), M0, h),
    lambda h: jaxsplit.symplectic_defect(jaxsplit.rk4(jaxsplit.harmonic_oscillator()), jnp.ones(2), h),
    lambda h: jaxsplit.orbit_symplectic_defect(STEP, M0, h),
    lambda h: jaxsplit.poisson_summary(STEP, jaxsplit.RigidBody(PHYSICAL), jnp.stack([M0, M0]), jnp.array([0.1, h])),
], ids=["poisson_defect", "symplectic_defect", "orbit_symplectic_defect", "poisson_summary"])
def test_every_structure_check_refuses_a_non_finite_step(check):
    for h in (math.nan, math.inf):
        _refused(lambda h=h: check(h), "finite")


# ---------------------------------------------------------------- counts and sizes: one bound-checker
def test_the_command_line_and_the_library_share_one_bound_checker():
    from jaxsplit import _bounds
    from jaxsplit.cli import _bounds as cli

    assert cli.at_most is _bounds.at_most and cli.MAX_STAGES == _bounds.MAX_STAGES
    assert cli.memory_limit is _bounds.memory_limit and cli.format_bytes is _bounds.format_bytes


@pytest.mark.parametrize("make,words", [
    (lambda: jaxsplit.triple_jump(16), ["triple_jump(16)", "3^7 stages", "1,000", "triple-jump-14 is the largest"]),
    (lambda: jaxsplit.triple_jump(40), ["triple_jump(40)", "3^19 stages"]),
    (lambda: jaxsplit.schemes["triple-jump-100000"], ["'triple-jump-100000'", "3^49,999 stages"]),
    (lambda: jaxsplit.schemes["triple-jump-" + "9" * 5000], ["3^((N-2)/2) stages"]),
    (lambda: splitting(jaxsplit.RigidBody(PHYSICAL), "triple-jump-16"), ["3^7 stages"]),
], ids=["16", "40", "100000", "5000-digits", "by-name-in-splitting"])
def test_a_scheme_whose_stages_exceed_the_bound_is_refused_before_it_is_built(make, words):
    _refused(make, *words)
    assert jaxsplit.triple_jump(14).stages == 729  # the largest allowed


def test_integrate_refuses_saved_states_beyond_the_memory_with_an_estimate():
    message = _refused(lambda: integrate(STEP, M0, 0.1, 10**12, save_every=1), "1,000,000,000,002",
                       "of 24 B", "TiB", "limit", "save_every=")
    assert "the memory available now" in message
    many = jnp.zeros((100_000, 3)) + M0  # 2.4 MB a state; 10^4 output times: 24 GB
    _refused(lambda: integrate(STEP, many, 0.1, ts=np.linspace(0.1, 1.0, 10_000)), "10,000", "2.3 MiB",
             "give fewer output times")


@pytest.mark.parametrize("kwargs,words", [
    ({"states": 10**9}, ["1,000,000,000 cases", "1,000,000,000 states x 1 ratios x 1 step sizes", "GiB",
                         "limit"]),
    ({"states": 10**6, "ratios": [(1.0, 0.5)] * 10, "step_sizes": [0.1] * 1000}, ["10,000,000,000 cases"]),
    ({"sampling": "random", "n_samples": 10**10}, ["10,000,000,000 cases", "n_samples"]),
    ({"states": True}, ["states", "integer"]),
], ids=["states-1e9", "product", "samples-1e10", "bool"])
def test_sweep_cases_bound_their_number_before_building_any(kwargs, words):
    _refused(lambda: jaxsplit.sweep_cases(**kwargs), *words)


def _family(log_inertia):
    return jaxsplit.RigidBody(jnp.exp(log_inertia), allow_nonphysical=True)


@pytest.mark.parametrize("kwargs,words", [
    ({"adam_steps": -1}, ["adam_steps", "-1"]), ({"adam_steps": 1.5}, ["adam_steps"]),
    ({"adam_steps": 2**40}, ["adam_steps", "int32"]), ({"lbfgs_iter": -1}, ["lbfgs_iter"]),
    ({"lbfgs_iter": True}, ["lbfgs_iter"]), ({"adam_lr": math.nan}, ["adam_lr", "finite"]),
    ({"adam_lr": 0.0}, ["adam_lr", "> 0"]), ({"tol": -1.0}, ["tol", ">= 0"]),
], ids=["adam--1", "adam-float", "adam-2^40", "lbfgs--1", "lbfgs-bool", "lr-nan", "lr-0", "tol-negative"])
def test_fit_refuses_bad_optimiser_settings_before_compiling(kwargs, words):
    t = np.linspace(0.0, 1.0, 5)
    _refused(lambda: jaxsplit.fit(_family, t, np.tile(np.asarray(M0), (5, 1)), jnp.zeros(3), **kwargs), *words)


@pytest.mark.parametrize("kwargs,words", [
    ({"noise": math.nan}, ["noise"]), ({"noise": -1.0}, ["noise", ">= 0"]), ({"seed": -1}, ["seed"]),
])
def test_simulate_refuses_bad_noise_and_seeds(kwargs, words):
    _refused(lambda: jaxsplit.simulate(_family, jnp.zeros(3), M0, np.linspace(0.0, 1.0, 5), **kwargs), *words)


# ---------------------------------------------------------------- gradients through output times
TS = jnp.array([0.25, 0.7])


def _loss(step, adjoint=None):
    return lambda m: jnp.sum(integrate(step, m, 0.1, ts=TS, adjoint=adjoint).x[:, 0])


GRADIENT_RTOL = 1e-12  # reverse (rebuilt states) against forward mode over a few steps: round-off


def test_reverse_mode_through_output_times_chooses_the_adjoint_that_works():
    """grad with the default adjoint works (the reversible one is chosen) and agrees with forward
    mode, which keeps the stored loop. Fails loudly if JAX stops tracing grad by linearization."""
    step = splitting(jaxsplit.RigidBody(PHYSICAL), "strang", "casimir", shift=1)  # two flows: compiles fastest
    chosen = jax.grad(_loss(step))(M0)
    forward = jax.jacfwd(_loss(step))(M0)
    np.testing.assert_allclose(chosen, forward, rtol=GRADIENT_RTOL, atol=GRADIENT_RTOL)


def test_reverse_mode_through_output_times_of_another_step_names_the_adjoint():
    rk4 = jaxsplit.rk4(jaxsplit.RigidBody(PHYSICAL))
    _refused(lambda: jax.grad(_loss(rk4))(M0), "adjoint='reversible'", "RungeKutta", "n_steps")
    assert jax.jacfwd(_loss(rk4))(M0).shape == (3,)


# ---------------------------------------------------------------- the diffrax solver refuses what integrate refuses
def test_the_diffrax_solver_refuses_what_integrate_refuses():
    diffrax = pytest.importorskip("diffrax")
    import jaxsplit.diffrax as jd

    body = jaxsplit.RigidBody(PHYSICAL)
    term, solver = jd.term(body), jd.Splitting("strang")
    _refused(lambda: diffrax.diffeqsolve(term, solver, 0.0, 1.0, 0.5, M0.astype(complex)), "y0 must be real")
    for terms in (diffrax.ODETerm(lambda t, y, args: body.vector_field(y)), diffrax.MultiTerm(term, term)):
        _refused(lambda terms=terms: diffrax.diffeqsolve(terms, solver, 0.0, 1.0, 0.5, M0), "jd.term(system, split)")
    sol = diffrax.diffeqsolve(term, solver, 0.0, 1.0, math.nan, M0, throw=False)
    assert sol.result == diffrax.RESULTS.nonfinite  # not successful with NaN (throw=True raises it)
