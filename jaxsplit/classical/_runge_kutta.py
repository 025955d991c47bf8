"""The seed paper's classical integrators (§2): Runge–Kutta methods from Butcher tableaus.

An s-stage method (2.3) with tableau (A, b, c) advances ẋ = f(x) by

    K_i = f(x_n + h Σ_j a_ij K_j),   x_{n+1} = x_n + h Σ_i b_i K_i.

Explicit tableaus (strictly lower-triangular A) are evaluated stage by stage. Implicit
ones solve the s·n stage equations G(K) = K − f(x + h (A ⊗ I) K) = 0 by Newton's method
with the full Jacobian from ``jax.jacfwd``, inside ``lax.while_loop``, until the Newton
increment reaches round-off (or stops decreasing). The solve is wrapped in
``lax.custom_root``, so derivatives (forward and reverse) come from the implicit function
theorem rather than from differentiating the iteration: the steps jit, vmap and
differentiate.

Named tableaus (Hairer–Nørsett–Wanner I, Hairer–Wanner II, Hairer–Lubich–Wanner GNI):
explicit Euler (2.4); the trapezoidal rule — the paper's "modified Euler" (2.5) printed as
(x_{n+1} − x_n)/h = f(x_n) + f(x_{n+1}) has no ½ and is then inconsistent (it approximates
the flow over 2h), so the consistent method (with ½) is implemented and the printed one
is kept as ``tableaus["modified-euler-as-printed"]`` (order 0) for the audit; implicit
midpoint = Gauss–Legendre 1 (2.2); Gauss–Legendre 2, 3 (and any s by collocation); classical
RK4; implicit Euler, Radau IIA (2 stages), Lobatto IIIA (3 stages); and a 2-stage DIRK
(two implicit midpoint half steps) that satisfies (2.7) without being Gauss–Legendre.

States may be any PyTree: the methods act on its floating leaves, raveled into one vector
(``jaxsplit.core.state.ravel``), so they apply to every system of the system layer.
"""

import dataclasses
import math
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..checks._tableau import ORDER_TOL, order_conditions
from ..core._errors import InputError
from ..core._flows import AbstractFlow
from ..core._state import as_state, ravel

_ROW_SUM_TOL = 1e-14


def _tuple2(a):
    return tuple(tuple(float(v) for v in row) for row in a)


@dataclasses.dataclass(frozen=True)
class ButcherTableau:
    """A Runge–Kutta tableau: frozen, hashable, validated when built.

    ``order`` is the declared classical order; it is verified against the Butcher
    order conditions (all rooted trees up to that order) in ``__post_init__``, and
    ``c`` must equal the row sums of ``A``. ``order=0`` marks an inconsistent method
    (kept only to study it). ``a`` (s rows of s floats), ``b`` and ``c`` (s floats) are tuples
    of Python floats: static data (a new tableau compiles anew; ``CoefficientRungeKutta``
    takes traced arrays). ``jaxsplit.tableaus`` holds the named ones.

    >>> import jaxsplit
    >>> heun = jaxsplit.ButcherTableau("heun", ((0.0, 0.0), (1.0, 0.0)), (0.5, 0.5), 2)
    >>> heun.stages, heun.explicit, jaxsplit.tableau_order(heun)
    (2, True, 2)
    """

    name: str
    a: tuple
    b: tuple
    order: int
    c: tuple | None = None
    citation: str = ""

    def __post_init__(self):
        try:
            a = np.asarray(self.a, dtype=float)
            b = np.asarray(self.b, dtype=float)
        except (TypeError, ValueError) as err:
            raise InputError(f"tableau {self.name!r}: A and b must be numeric, got {self.a!r}, {self.b!r}") from err
        s = b.shape[0] if b.ndim == 1 else -1
        if s < 1 or a.shape != (s, s):
            raise InputError(f"tableau {self.name!r}: A must be s x s and b of length s, got {a.shape}, {b.shape}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise InputError(f"tableau {self.name!r}: coefficients must be finite")
        row_sums = a.sum(axis=1)
        c = row_sums if self.c is None else np.asarray(self.c, dtype=float)
        if c.shape != (s,) or np.max(np.abs(c - row_sums)) > _ROW_SUM_TOL * max(1.0, np.max(np.abs(a))):
            raise InputError(f"tableau {self.name!r}: c must equal the row sums of A {row_sums.tolist()}, got {c.tolist()}")
        if isinstance(self.order, bool) or not isinstance(self.order, int) or self.order < 0:
            raise InputError(f"tableau {self.name!r}: order must be an integer >= 0, got {self.order!r}")
        object.__setattr__(self, "a", _tuple2(a))
        object.__setattr__(self, "b", tuple(float(v) for v in b))
        object.__setattr__(self, "c", tuple(float(v) for v in c))
        bad = [cond for cond in order_conditions((a, b), self.order) if abs(cond.residual) > ORDER_TOL]
        if bad:
            raise InputError(
                f"tableau {self.name!r}: declared order {self.order} but the condition for tree {bad[0].tree} "
                f"has residual {bad[0].residual:.3g}"
            )

    @property
    def stages(self) -> int:
        return len(self.b)

    @property
    def explicit(self) -> bool:
        return all(self.a[i][j] == 0.0 for i in range(self.stages) for j in range(i, self.stages))


def _gauss_collocation(s: int):
    """Gauss–Legendre collocation coefficients for any s (NumPy, float64)."""
    x, _ = np.polynomial.legendre.leggauss(s)
    c = (x + 1) / 2
    v = np.vander(c, s, increasing=True).T  # v[k, j] = c_j^k
    k = np.arange(1, s + 1)
    b = np.linalg.solve(v, 1.0 / k)
    a = np.linalg.solve(v, (c[None, :] ** k[:, None] / k[:, None])).T
    return a, b


_S3, _S15 = math.sqrt(3.0), math.sqrt(15.0)

_GAUSS = {
    1: ((( 0.5,),), (1.0,)),
    2: (((0.25, 0.25 - _S3 / 6), (0.25 + _S3 / 6, 0.25)), (0.5, 0.5)),
    3: (((5 / 36, 2 / 9 - _S15 / 15, 5 / 36 - _S15 / 30),
         (5 / 36 + _S15 / 24, 2 / 9, 5 / 36 - _S15 / 24),
         (5 / 36 + _S15 / 30, 2 / 9 + _S15 / 15, 5 / 36)), (5 / 18, 4 / 9, 5 / 18)),
}


def gauss_legendre_tableau(stages: int) -> ButcherTableau:
    """The s-stage Gauss–Legendre ``ButcherTableau``, order 2s (closed forms for s <= 3,
    collocation in float64 beyond).

    >>> import jaxsplit
    >>> t = jaxsplit.gauss_legendre_tableau(2)
    >>> t.order, t.stages, jaxsplit.condition_2_7_defect(t) < 1e-15
    (4, 2, True)
    """
    if isinstance(stages, bool) or not isinstance(stages, (int, np.integer)) or not 1 <= stages <= 8:
        raise InputError(f"Gauss-Legendre stages must be an integer in 1..8, got {stages!r}")
    stages = int(stages)
    a, b = _GAUSS[stages] if stages in _GAUSS else _gauss_collocation(stages)
    name = "implicit-midpoint" if stages == 1 else f"gauss-legendre-{stages}"
    return ButcherTableau(name, a, b, 2 * stages, citation="Butcher 1964; HNW I Table 7.4; seed paper (2.2) for s = 1")


tableaus: dict[str, ButcherTableau] = {
    t.name: t
    for t in (
        ButcherTableau("explicit-euler", ((0.0,),), (1.0,), 1, citation="seed paper (2.4)"),
        ButcherTableau("implicit-euler", ((1.0,),), (1.0,), 1, citation="HW II IV.5"),
        ButcherTableau("trapezoid", ((0.0, 0.0), (0.5, 0.5)), (0.5, 0.5), 2,
                       citation="Lobatto IIIA-2; the seed paper's 'modified Euler' (2.5) with its missing 1/2"),
        ButcherTableau("modified-euler-as-printed", ((0.0, 0.0), (1.0, 1.0)), (1.0, 1.0), 0,
                       citation="seed paper (2.5) exactly as printed (inconsistent: sum b = 2)"),
        gauss_legendre_tableau(1),
        gauss_legendre_tableau(2),
        gauss_legendre_tableau(3),
        ButcherTableau("rk4", ((0, 0, 0, 0), (0.5, 0, 0, 0), (0, 0.5, 0, 0), (0, 0, 1, 0)),
                       (1 / 6, 1 / 3, 1 / 3, 1 / 6), 4, citation="Kutta 1901, classical RK4"),
        ButcherTableau("radau-iia-2", ((5 / 12, -1 / 12), (0.75, 0.25)), (0.75, 0.25), 3,
                       citation="Ehle 1969; HW II Table 5.5"),
        ButcherTableau("lobatto-iiia-3", ((0, 0, 0), (5 / 24, 1 / 3, -1 / 24), (1 / 6, 2 / 3, 1 / 6)),
                       (1 / 6, 2 / 3, 1 / 6), 4, citation="Ehle 1969; HW II Table 5.7"),
        ButcherTableau("midpoint-composition-2", ((0.25, 0.0), (0.5, 0.25)), (0.5, 0.5), 2,
                       citation="two implicit-midpoint half steps as one DIRK; satisfies (2.7)"),
    )
}


# ------------------------------------------------------------------ the stepper
def _field(system) -> Callable:
    if hasattr(system, "vector_field"):
        return system.vector_field
    if callable(system):
        return system
    raise InputError(f"system must have a vector_field(x) method or be a function f(x), got {type(system).__name__}")


def _flat_problem(system, x):
    """(x as a flat vector, the field on flat vectors, unravel): RK acts on any PyTree state."""
    f = _field(system)
    flat, unravel = ravel(as_state(x, "x"))

    def flat_field(v):
        return ravel(f(unravel(v)))[0]

    return flat, flat_field, unravel


class NewtonInfo(NamedTuple):
    """Diagnostics of one stage solve: Newton iterations, max|G(K)|, last max|ΔK|."""

    iterations: jax.Array
    residual: jax.Array
    increment: jax.Array


def _newton(g, z0, max_iter: int):
    """Full Newton on g(z) = 0 until the increment is at round-off or stops decreasing."""
    eps = jnp.finfo(z0.dtype).eps
    inf = jnp.asarray(jnp.inf, z0.dtype)

    def cond(state):
        z, dz, dz_prev, it = state
        scale = jnp.max(jnp.abs(z)) + jnp.finfo(z.dtype).tiny
        converged = dz <= 4 * eps * scale
        stalled = (it >= 3) & (dz >= dz_prev)
        return (it < max_iter) & ~converged & ~stalled

    def body(state):
        z, dz, _, it = state
        step = jnp.linalg.solve(jax.jacfwd(g)(z), -g(z))
        return z + step, jnp.max(jnp.abs(step)), dz, it + 1

    z, dz, _, it = jax.lax.while_loop(cond, body, (z0, inf, inf, jnp.asarray(0)))
    return z, it, dz


def _tangent_solve(g, y):
    return jnp.linalg.solve(jax.jacfwd(g)(y), y)


def _stage_residual(f, x, h, a, s):
    n = x.shape[0]

    def g(z):
        k = z.reshape(s, n)
        return (k - jax.vmap(f)(x[None, :] + h * (a @ k))).reshape(-1)

    return g


def _solve_stages(g, z0, max_iter):
    return jax.lax.custom_root(g, z0, lambda g_, z_: _newton(g_, z_, max_iter)[0], _tangent_solve)


class RungeKutta(AbstractFlow):
    """One step ``step(x, h)`` of the tableau on ``system`` (a module: its parameters trace).

    Acts on any PyTree state (on its floating leaves, raveled; result of the same structure
    and dtypes). A flow in the composer's sense, but not an exact one-parameter group: it is
    never merged. Traced: the system's array fields, ``x``, ``h``; static: the tableau and
    ``max_iter`` (Newton iterations of implicit stages, differentiated by the implicit
    function theorem). ``stage_derivatives`` and ``newton_info`` expose the stage solve.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> step = jaxsplit.runge_kutta(body, "implicit-midpoint")
    >>> m1 = step(m0, 0.1)
    >>> float(abs(body.casimir(m1) - body.casimir(m0))) < 1e-15           # quadratic invariants kept
    True
    >>> int(step.newton_info(m0, 0.1).iterations) <= 10
    True
    """

    system: object
    tableau: ButcherTableau = eqx.field(static=True)
    max_iter: int = eqx.field(static=True, default=50)

    @property
    def is_group(self) -> bool:
        return False

    def _stages(self, flat, f, h):
        dtype = flat.dtype
        a = jnp.asarray(self.tableau.a, dtype=dtype)
        s = self.tableau.stages
        if self.tableau.explicit:
            ks = []
            for i in range(s):
                y = flat
                for j in range(i):
                    if self.tableau.a[i][j] != 0.0:
                        y = y + (h * a[i, j]) * ks[j]
                ks.append(f(y))
            return jnp.stack(ks)
        g = _stage_residual(f, flat, h, a, s)
        return _solve_stages(g, jnp.tile(f(flat), s), self.max_iter).reshape(s, -1)

    def stage_derivatives(self, x, h):
        """The K_i (shape (s, n), n the number of floating components) of one step from ``x``."""
        flat, f, _ = _flat_problem(self.system, x)
        return self._stages(flat, f, jnp.asarray(h, dtype=flat.dtype))

    def newton_info(self, x, h) -> NewtonInfo:
        """Iterations, final residual max|G(K)| and last increment of the stage solve."""
        flat, f, _ = _flat_problem(self.system, x)
        h = jnp.asarray(h, dtype=flat.dtype)
        g = _stage_residual(f, flat, h, jnp.asarray(self.tableau.a, dtype=flat.dtype), self.tableau.stages)
        if self.tableau.explicit:
            z = self._stages(flat, f, h).reshape(-1)
            return NewtonInfo(jnp.asarray(0), jnp.max(jnp.abs(g(z))), jnp.asarray(0.0, flat.dtype))
        z, it, dz = _newton(g, jnp.tile(f(flat), self.tableau.stages), self.max_iter)
        return NewtonInfo(it, jnp.max(jnp.abs(g(z))), dz)

    def __call__(self, x, h):
        flat, f, unravel = _flat_problem(self.system, x)
        h = jnp.asarray(h, dtype=flat.dtype)
        k = self._stages(flat, f, h)
        return unravel(flat + h * (jnp.asarray(self.tableau.b, dtype=flat.dtype) @ k))


def runge_kutta(system, tableau: "ButcherTableau | str", *, max_iter: int = 50) -> RungeKutta:
    """The Runge–Kutta step (2.3) of ``tableau`` (a ``ButcherTableau`` or a name in ``tableaus``)
    for ``system`` (any system of the system layer, or any f(x) -> ẋ): a ``RungeKutta``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> step = jaxsplit.runge_kutta(body, "gauss-legendre-2")
    >>> jaxsplit.integrate(step, m0, 0.1, 10).final.shape
    (3,)
    >>> round(float(jaxsplit.runge_kutta(lambda x: -x, "rk4")(jnp.array([1.0]), 0.1)[0]), 8)   # any f(x)
    0.9048375
    """
    if isinstance(tableau, str):
        if tableau not in tableaus:
            raise InputError(f"unknown tableau {tableau!r}; known: {', '.join(tableaus)}")
        tableau = tableaus[tableau]
    if not isinstance(tableau, ButcherTableau):
        raise InputError(f"tableau must be a ButcherTableau or a name, got {type(tableau).__name__}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise InputError(f"max_iter must be a positive integer, got {max_iter!r}")
    _field(system)
    return RungeKutta(system, tableau, max_iter)


class CoefficientRungeKutta(AbstractFlow):
    """A Runge–Kutta step whose coefficients (A, b) are ARRAYS (traced), not static data.

    Every tableau, explicit or not, is solved by the same Newton iteration (for a strictly
    lower-triangular A it terminates in at most s iterations), so one compilation serves a
    whole family of tableaus of the same size: ``vmap`` over coefficients (pad smaller
    tableaus with zero rows/weights), or differentiate with respect to them. ``a`` (s, s),
    ``b`` (s,) floating arrays (traced); state and ``h`` as for ``RungeKutta``.

    >>> import jax, jax.numpy as jnp, jaxsplit
    >>> step = jaxsplit.runge_kutta_coefficients(lambda x: -x, jnp.array([[0.5]]), jnp.array([1.0]))  # midpoint
    >>> round(float(step(jnp.array([1.0]), 0.1)[0]), 12)                                      # (1 - h/2)/(1 + h/2)
    0.904761904762
    >>> x1 = lambda b: jaxsplit.runge_kutta_coefficients(lambda x: -x, jnp.array([[0.5]]), b)(jnp.array([1.0]), 0.1)
    >>> jax.grad(lambda b: x1(b)[0])(jnp.array([1.0])).round(12).tolist()     # d x1 / d b = h K
    [-0.095238095238]
    """

    system: object
    a: jax.Array
    b: jax.Array
    max_iter: int = eqx.field(static=True, default=50)

    @property
    def is_group(self) -> bool:
        return False

    def __call__(self, x, h):
        flat, f, unravel = _flat_problem(self.system, x)
        h = jnp.asarray(h, dtype=flat.dtype)
        a, b = jnp.asarray(self.a, dtype=flat.dtype), jnp.asarray(self.b, dtype=flat.dtype)
        s = b.shape[0]
        z = _solve_stages(_stage_residual(f, flat, h, a, s), jnp.tile(f(flat), s), self.max_iter)
        return unravel(flat + h * (b @ z.reshape(s, -1)))


def runge_kutta_coefficients(system, a, b, *, max_iter: int = 50) -> CoefficientRungeKutta:
    """A ``CoefficientRungeKutta`` step from coefficient arrays ``a`` (s, s) and ``b`` (s,), which
    may be traced (``vmap`` over tableaus, ``grad`` in the coefficients).

    >>> import jax.numpy as jnp, jaxsplit
    >>> a, b = jnp.array([[0.0, 0.0], [1.0, 0.0]]), jnp.array([0.5, 0.5])            # Heun
    >>> round(float(jaxsplit.runge_kutta_coefficients(lambda x: -x, a, b)(jnp.array([1.0]), 0.1)[0]), 12)
    0.905
    """
    a, b = jnp.asarray(a), jnp.asarray(b)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or b.shape != a.shape[:1]:
        raise InputError(f"A must be s x s and b of length s, got shapes {a.shape} and {b.shape}")
    _field(system)
    return CoefficientRungeKutta(system, a, b, max_iter)


def padded_coefficients(tableau: ButcherTableau, stages: int):
    """(A, b) of ``tableau`` padded with zero stages to ``stages`` (same method)."""
    s = tableau.stages
    if stages < s:
        raise InputError(f"cannot pad a {s}-stage tableau to {stages} stages")
    a = np.zeros((stages, stages))
    a[:s, :s] = np.asarray(tableau.a)
    b = np.zeros(stages)
    b[:s] = tableau.b
    return a, b


def explicit_euler(system) -> RungeKutta:
    """Explicit Euler (2.4), x_{n+1} = x_n + h f(x_n), as a ``RungeKutta`` step for ``system``.
    On the free body |m|² grows by exactly h²|f(m)|² a step (f ⊥ m).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> m1 = jaxsplit.explicit_euler(body)(m0, 0.1)
    >>> f = body.vector_field(m0)
    >>> bool(jnp.isclose(m1 @ m1 - m0 @ m0, 0.01 * f @ f, rtol=1e-12))
    True
    """
    return runge_kutta(system, "explicit-euler")


def trapezoid(system) -> RungeKutta:
    """The trapezoidal rule x_{n+1} = x_n + h/2 (f(x_n) + f(x_{n+1})): the consistent form of (2.5),
    as an implicit ``RungeKutta`` step. Not Poisson: it drifts off the Casimir's sphere.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> m1 = jaxsplit.trapezoid(body)(m0, 0.1)
    >>> float(abs(body.casimir(m1) - body.casimir(m0))) > 1e-8
    True
    """
    return runge_kutta(system, "trapezoid")


def gauss_legendre(system, stages: int = 1) -> RungeKutta:
    """Gauss–Legendre with ``stages`` stages (order 2s, static); s = 1 is the implicit midpoint
    rule (2.2). Keeps every quadratic invariant (H and C of the free body) to round-off.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> sol = jaxsplit.integrate(jaxsplit.gauss_legendre(body, 2), m0, 0.1, 50)
    >>> float(abs(body.hamiltonian(sol.final) / body.hamiltonian(m0) - 1)) < 1e-14
    True
    """
    return runge_kutta(system, gauss_legendre_tableau(stages))


def rk4(system) -> RungeKutta:
    """The classical fourth-order Runge–Kutta method for ``system`` (a ``RungeKutta`` step).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> jaxsplit.rk4(body)(m0, 0.1).shape
    (3,)
    """
    return runge_kutta(system, "rk4")
