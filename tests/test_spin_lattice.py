"""Spin lattices: geometry (colourings), the sign convention, exact bond flows (Poisson defect,
agreement with the vector field, orders), long runs; and the one-line errors.

Cost: the compiled programs are few and shared (the orders of four schemes and their
reference run one rolled composition, traced step count: one compilation); the Poisson
defects run eagerly on lattices of the same size, sharing JAX's per-operation cache.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.lattices import graph, lattice
from jaxsplit.lattices._graph import degrees, is_proper, misra_gries

ROUND_OFF = 1e-13  # acceptance: Poisson defect and |S_i| drift at float64 round-off
ORDER_SLACK = 0.3  # acceptance: measured order within 0.3 of nominal

ALL_TERMS = {"exchange": 0.8, "anisotropic": 0.3, "dm": (0.2, -0.1, 0.35), "anisotropy": 0.4,
             "axis": (1.0, 1.0, 1.0), "field": (0.1, -0.2, 0.3)}


# ------------------------------------------------------------------ geometry
@pytest.mark.parametrize("name, colours", [("chain", 2), ("square", 4), ("triangular", 6), ("honeycomb", 3),
                                           ("simple-cubic", 6)])
def test_named_lattices_are_coloured_optimally(name, colours):
    for periodic in (True, False):
        lat = lattice(name, 4, periodic)
        assert is_proper(lat.n_sites, lat.bonds, lat.colours)
        assert len(lat.colours) == lat.max_degree == colours
        assert lat.positions.shape == (lat.n_sites, lat.dimension) and int(np.prod(lat.shape)) == lat.n_sites
    odd = lattice(name, 3 if name != "honeycomb" else 5, True)  # odd cycles: Δ + 1 at most
    assert is_proper(odd.n_sites, odd.bonds, odd.colours) and len(odd.colours) <= odd.max_degree + 1


def test_bond_lengths_are_one():
    for name in ("chain", "square", "triangular", "honeycomb", "simple-cubic"):
        lat = lattice(name, 4, periodic=False)
        lengths = np.linalg.norm(lat.positions[lat.bonds[:, 0]] - lat.positions[lat.bonds[:, 1]], axis=1)
        np.testing.assert_allclose(lengths, 1.0, atol=1e-12)


@pytest.mark.parametrize("name", ["chain", "square", "triangular", "honeycomb", "simple-cubic"])
def test_small_periodic_boxes_are_refused_exactly_when_the_bond_list_is_not_simple(name):
    """``lattices._lattices.simple`` decides from the offsets alone; the oracle builds every bond of
    the wrapped box by brute force and asks ``check_bonds`` (self-loops, repeated pairs)."""
    import itertools

    from jaxsplit.lattices._graph import check_bonds
    from jaxsplit.lattices._lattices import UNIT_CELLS

    cell, basis, types = UNIT_CELLS[name]
    d, nb = cell.shape[0], len(basis)
    for size in itertools.product(*([range(1, 5 if d < 3 else 4)] * d)):
        bonds = [(np.ravel_multi_index(c, size) * nb + a,
                  np.ravel_multi_index(tuple(np.mod(np.add(c, o), size)), size) * nb + b)
                 for c in itertools.product(*map(range, size)) for a, b, o in types]
        try:
            check_bonds(int(np.prod(size)) * nb, bonds)
            oracle = True
        except jaxsplit.InputError:
            oracle = False
        try:
            lat = lattice(name, size)
            assert oracle, (name, size)
            assert lat.n_bonds == len(bonds)
            assert is_proper(lat.n_sites, lat.bonds, lat.colours)
        except jaxsplit.InputError as err:
            assert not oracle and "needs at least" in str(err), (name, size, err)


def test_any_graph_gets_at_most_delta_plus_one_colours():
    rng = np.random.default_rng(7)
    for _ in range(60):
        n = int(rng.integers(3, 25))
        pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if rng.uniform() < rng.uniform(0.1, 0.7)])
        if len(pairs) == 0:
            continue
        rng.shuffle(pairs)
        colours = misra_gries(n, pairs)
        assert is_proper(n, pairs, colours)
        assert len(colours) <= degrees(n, pairs).max() + 1
    petersen = graph(10, [[i, (i + 1) % 5] for i in range(5)] + [[i, i + 5] for i in range(5)]
                     + [[5 + i, 5 + (i + 2) % 5] for i in range(5)])
    assert len(petersen.colours) == 4  # class 2: Δ + 1 = 4 needed, and reached


@pytest.mark.parametrize("call, message", [
    (lambda: lattice("kagome", 4), "unknown lattice 'kagome'"),
    (lambda: lattice("square", "4x"), "size must be like 64 or 64x64"),
    (lambda: lattice("square", (4, 4, 4)), "a square lattice has 2 axes"),
    (lambda: lattice("chain", 0), "size must be >= 1"),
    (lambda: lattice("chain", 2), "needs at least 3 cells per axis"),
    (lambda: graph(3, [[0, 1], [1, 0]]), "appears 2 times"),
    (lambda: graph(3, [[0, 3]]), "must lie in 0..2"),
    (lambda: graph(3, [[1, 1]]), "joins site 1 to itself"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4), exchange=[1.0, 2.0]), "exchange must be a number or one per bond"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4), spin_length=0.0), "spin_length must be > 0"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4), axis=(0, 0, 0)), "axis (the anisotropy axis n) must be"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4), field=(0.0, np.nan, 0.0)), "field must be finite"),
    (lambda: jaxsplit.spin_lattice("chain"), "spin_lattice needs a lattice"),
    (lambda: jaxsplit.spin_lattice(lattice("triangular", 4)).neel(), "needs a bipartite lattice"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4)).check_state(jnp.ones((4, 3))), "|S_i| must equal spin_length"),
    (lambda: jaxsplit.spin_lattice(lattice("chain", 4)).check_state(jnp.ones((5, 3))), "has shape (4, 3)"),
    (lambda: jaxsplit.splitting(jaxsplit.spin_lattice(lattice("square", 20)), "strang", "sweep"),
     "at most 256 sites"),
    (lambda: jaxsplit.splitting(jaxsplit.spin_lattice(lattice("chain", 4)), "strang", "axes"),
     "a spin lattice has no body axes"),
])
def test_bad_input_gets_one_line(call, message):
    with pytest.raises(jaxsplit.InputError) as err:
        call()
    assert message in str(err.value) and "\n" not in str(err.value)


# ------------------------------------------------------------------ convention
def test_bracket_and_precession_sense():
    """{S^x, S^y} = +S^z, and a spin in B = B e_z precesses with angular velocity −B:
    S(t) = (cos Bt, −sin Bt, 0) from e_x, by the Zeeman flow, the vector field and the split."""
    b = 0.7
    one = jaxsplit.spin_lattice(graph(1, np.zeros((0, 2), int)), field=(0.0, 0.0, b))
    s = jnp.array([[0.3, -0.5, 0.8]])
    pick = [lambda x, k=k: x[0, k] for k in range(3)]
    assert float(one.bracket(pick[0], pick[1], s)) == pytest.approx(0.8, abs=1e-15)
    assert float(one.bracket(pick[1], pick[2], s)) == pytest.approx(0.3, abs=1e-15)
    e_x = jnp.array([[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(one.vector_field(e_x), [[0.0, -b, 0.0]], atol=1e-15)
    t = 1.3
    (flow,) = one.split("bonds")
    np.testing.assert_allclose(flow(e_x, t), [[np.cos(b * t), -np.sin(b * t), 0.0]], atol=1e-15)


def test_vector_field_is_the_poisson_form_and_conserves_energy():
    system = jaxsplit.spin_lattice(lattice("honeycomb", 2), **ALL_TERMS)
    s = system.random_state(seed=2)
    generic = jaxsplit.AbstractSystem.vector_field(system, s)  # Π(x) ∇H(x) from poisson_matrix
    np.testing.assert_allclose(system.vector_field(s), generic, atol=1e-14)
    grad = jax.grad(system.hamiltonian)(s)
    assert abs(float(jnp.sum(grad * system.vector_field(s)))) < 1e-14


# ------------------------------------------------------------------ exact bond flows
LATTICES_16 = [("chain", 16), ("square", (4, 4)), ("triangular", (4, 4)), ("honeycomb", (2, 4))]


@pytest.mark.parametrize("name, size", LATTICES_16)
def test_bond_split_is_a_poisson_map(name, size):
    """Every term at once (per-bond random exchange and DM vectors): each piece is exact."""
    lat = lattice(name, size)
    rng = np.random.default_rng(len(name))
    system = jaxsplit.spin_lattice(lat, **{**ALL_TERMS, "exchange": rng.normal(size=lat.n_bonds),
                                           "dm": rng.normal(scale=0.4, size=(lat.n_bonds, 3))})
    step = jaxsplit.splitting(system, "strang", "bonds")
    assert len(step.flows) == 3 * len(lat.colours) + 2  # exchange, DM's Ising part, XXZ per colour; K, B
    s0 = system.random_state(seed=5)
    assert float(jaxsplit.poisson_defect(step, system, s0, 0.2)) < ROUND_OFF


def _rolled_runner(step, length):
    """One compiled run for every scheme over ``step``'s flows and every step count."""
    rolled = jaxsplit.roll(step, length)

    @jax.jit
    def run(pieces, weights, x0, h, n):
        flow = jaxsplit.RolledComposition(rolled.flows, pieces, weights)
        return jax.lax.fori_loop(0, n, lambda _, x: flow(x, h), x0)

    return run


def test_bond_split_solves_the_equations_and_has_the_orders():
    system = jaxsplit.spin_lattice(lattice("chain", 6), **ALL_TERMS)
    s0 = system.random_state(seed=3)
    names = {"strang": (2, jaxsplit.ladder(80, 16.0, 6)), "triple-jump-4": (4, jaxsplit.ladder(16, 16.0, 6)),
             "kahan-li-6": (6, jaxsplit.ladder(6, 10.0, 6)), "kahan-li-8": (8, [6, 10, 16, 25])}
    steps = {n: jaxsplit.splitting(system, n, "bonds") for n in names}
    length = max(len(s.word) for s in steps.values())
    run = _rolled_runner(steps["strang"], length)

    def solve(name, t_end, count):
        rolled = jaxsplit.roll(steps[name], length)
        return run(rolled.pieces, rolled.weights, s0, t_end / count, count)

    # the splitting solves Ṡ_i = ∂H/∂S_i × S_i: Strang converges (order 2) to classical RK4's solution
    rk4 = jaxsplit.integrate(jaxsplit.rk4(system), s0, 0.5 / 2000, 2000).final
    e1, e2 = (float(jnp.max(jnp.abs(solve("strang", 0.5, n) - rk4))) for n in (40, 80))
    assert e1 < 1e-3 and 3.7 < e1 / e2 < 4.3
    t_end = 2.0
    reference = solve("kahan-li-8", t_end, 400)
    for name, (order, counts) in names.items():
        errors = [float(jnp.max(jnp.abs(solve(name, t_end, n) - reference))) for n in counts]
        fit = jaxsplit.fit_order(t_end / np.array(counts), errors)
        assert abs(fit.order - order) <= ORDER_SLACK, (name, fit.order, errors)


def test_long_run_keeps_lengths_and_bounded_energy():
    """10⁵ Strang steps of exchange, anisotropy and field (7 rotations a step: |S_i| is a
    random walk of round-off, ~1e-16 √(7·10⁵); with all five terms, 27 rotations a step, it
    reached 1.1e-13)."""
    system = jaxsplit.spin_lattice(lattice("square", (2, 4), periodic=False), exchange=0.8, anisotropy=0.4,
                                   axis=(1.0, 1.0, 1.0), field=(0.1, -0.2, 0.3), spin_length=1.5)
    s0 = system.random_state(seed=4)
    step = jaxsplit.splitting(system, "strang", "bonds")
    h, blocks, per_block = 0.05, 1000, 100  # 10⁵ steps

    @jax.jit
    def run(x0):
        def block(x, _):
            x = jax.lax.fori_loop(0, per_block, lambda _, y: step(y, h), x)
            return x, (system.hamiltonian(x), jnp.max(jnp.abs(jnp.linalg.norm(x, axis=-1) / 1.5 - 1)))
        return jax.lax.scan(block, x0, length=blocks)[1]

    energy, length_error = run(s0)
    assert float(jnp.max(length_error)) < ROUND_OFF
    error = np.abs(np.asarray(energy) - float(system.hamiltonian(s0)))
    assert 1e-6 < error.max() < 5e-2  # a splitting's error: present and bounded
    # not growing: the mean error of the two halves (their ratio 0.94-1.03 over seeds 4-8 and
    # either CPU emitter; the maximum, an extreme of a chaotic fluctuation, ranged 0.81-1.71)
    first, second = error[: blocks // 2].mean(), error[blocks // 2:].mean()
    assert second < 1.2 * first, (first, second)
    t = h * per_block * np.arange(1, blocks + 1)
    drift = abs(np.polyfit(t, np.asarray(energy), 1)[0]) * t[-1]
    assert drift < 0.1 * error[: blocks // 2].max()


def test_lattice_shaped_float32_state_keeps_shape_and_dtype():
    system = jaxsplit.spin_lattice(lattice("honeycomb", (2, 3)), exchange=-1.0, field=(0.0, 0.0, 0.2))
    s0 = system.neel(dtype=jnp.float32).reshape(system.lattice.shape + (3,))
    s0 = system.perturbed(s0, 0.1, seed=1)
    out = jaxsplit.integrate(jaxsplit.splitting(system, "strang", "bonds"), s0, 0.05, 20).final
    assert out.shape == (2, 3, 2, 3) and out.dtype == jnp.float32
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(out, axis=-1) - 1))) < 1e-6
