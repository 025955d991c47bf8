"""Hamilton–Poisson systems on Rⁿ: ẋ = Π(x) ∇H(x), with ∇H by ``jax.grad``.

A system is two pure functions of the state x ∈ Rⁿ: the Poisson matrix Π(x) (n × n,
skew, satisfying the Jacobi identity) and the Hamiltonian H(x), plus optional named
Casimirs / first integrals for the invariant monitors. Parameters that should be traced
(swept by ``vmap``, differentiated by ``grad``) are passed by making the functions
``jax.tree_util.Partial`` objects: their bound arguments are PyTree leaves.

Instances from the seed paper:

* ``rigid_body_system(inertia)`` — so(3)*, Π(m) = hat(m), H = ½ Σ m_i²/I_i, C = ½|m|²;
* ``harmonic_oscillator()`` — Example 2.1, x = (q, p), Π = J = [[0, 1], [−1, 0]],
  H = ½(q² + p²);
* ``example_3_1(A, B, C)`` — Example 3.1, Π(x) = [[0, x₂], [−x₂, 0]] (NOT constant),
  H = A x₁ + B x₂ + C, so ẋ = (B x₂, −A x₂): a linear vector field;
* ``canonical_system(hamiltonian, dim)`` and ``constant_poisson_system(matrix, hamiltonian)``
  for Propositions 2.1–3.2 (any H, constant Π).
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ._base import AbstractSystem
from ._rigid_body import as_body
from .so3 import hat

Partial = jax.tree_util.Partial


class HamiltonPoisson(AbstractSystem):
    """A Hamilton–Poisson system (Rⁿ, Π, H) from two functions; ``vector_field(x) = Π(x) ∇H(x)``.

    ``invariants`` maps names to functions x -> scalar that the flow conserves (H is
    always monitored as ``"energy"``). It offers no split: its steps are Runge–Kutta
    methods (``jaxsplit.runge_kutta``) or flows the user composes.

    >>> import jax.numpy as jnp, jaxsplit
    >>> inertia = jnp.array([2.0, 1.0, 2 / 3])
    >>> body = jaxsplit.HamiltonPoisson(jaxsplit.hat, lambda m: 0.5 * jnp.sum(m**2 / inertia),
    ...                                 {"casimir": lambda m: m @ m})
    >>> m = jnp.array([0.4, -0.3, 0.8])
    >>> body.vector_field(m)                      # Π(m) ∇H(m) = m × I⁻¹m
    Array([-0.12, -0.32, -0.06], dtype=float64)
    >>> sorted(body.invariants())
    ['casimir', 'energy']
    >>> bool(jaxsplit.poisson_defect(jaxsplit.rk4(body), body, m, 0.1) > 1e-9)   # RK4 is not Poisson
    True
    """

    poisson_fn: Callable
    hamiltonian_fn: Callable
    declared: tuple
    label: str = eqx.field(static=True)

    def __init__(self, poisson_matrix, hamiltonian, invariants=(), name: str = "hamilton-poisson"):
        if not callable(poisson_matrix) or not callable(hamiltonian):
            raise InputError("HamiltonPoisson needs callables poisson_matrix(x) and hamiltonian(x)")
        inv = tuple(invariants.items()) if isinstance(invariants, dict) else tuple(invariants)
        for item in inv:
            if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str) and callable(item[1])):
                raise InputError(f"invariants must be (name, function) pairs, got {item!r}")
        self.poisson_fn, self.hamiltonian_fn, self.declared, self.label = poisson_matrix, hamiltonian, inv, name

    @property
    def name(self) -> str:
        return self.label

    def poisson_matrix(self, x):
        return self.poisson_fn(x)

    def hamiltonian(self, x):
        return self.hamiltonian_fn(x)

    def invariants(self):
        return {"energy": self.hamiltonian_fn, **dict(self.declared)}

    def gradient(self, x):
        return jax.grad(self.hamiltonian_fn)(x)


# ---------------------------------------------------------------- the rigid body
def _rb_energy(inertia, m):
    return 0.5 * jnp.sum(m * m / jnp.asarray(inertia, dtype=m.dtype))


def _half_square(x):
    return 0.5 * jnp.sum(x * x)


def rigid_body_system(inertia) -> HamiltonPoisson:
    """The free rigid body on so(3)* (``inertia`` or a ``RigidBody``), Casimir C = ½|m|².

    >>> import jax.numpy as jnp, jaxsplit
    >>> system = jaxsplit.rigid_body_system(jaxsplit.STANDARD_CASE.body())      # I = (2, 1, 2/3)
    >>> system.vector_field(jnp.array([0.4, -0.3, 0.8]))
    Array([-0.12, -0.32, -0.06], dtype=float64)
    >>> float(jaxsplit.poisson_defect(jaxsplit.explicit_euler(system), system, jnp.array([0.4, -0.3, 0.8]), 0.1))
    0.00156..."""
    body = as_body(inertia)
    return HamiltonPoisson(hat, Partial(_rb_energy, body.inertia), (("casimir", _half_square),),
                           "rigid-body")


# ---------------------------------------------------------------- canonical systems
def canonical_matrix(dim: int, dtype=None):
    """J = [[0, I], [−I, 0]] for x = (q, p) ∈ R^{2m}."""
    if not (isinstance(dim, (int, np.integer)) and dim >= 2 and dim % 2 == 0):
        raise InputError(f"a canonical system needs an even dimension >= 2, got {dim!r}")
    m = dim // 2
    eye, zero = jnp.eye(m, dtype=dtype), jnp.zeros((m, m), dtype=dtype)
    return jnp.block([[zero, eye], [-eye, zero]])


def _canonical_pi(dim, x):
    return canonical_matrix(int(dim), x.dtype)


def canonical_system(hamiltonian: Callable, dim: int, name: str = "canonical") -> HamiltonPoisson:
    """(R^{2m}, J, H) with x = (q, p): q̇ = ∂H/∂p, ṗ = −∂H/∂q.

    >>> import jax.numpy as jnp, jaxsplit
    >>> pendulum = jaxsplit.canonical_system(lambda x: 0.5 * x[1] ** 2 - jnp.cos(x[0]), 2)
    >>> pendulum.vector_field(jnp.array([0.5, 1.0]))          # (q̇, ṗ) = (p, −sin q)
    Array([ 1.        , -0.47942554], dtype=float64)"""
    canonical_matrix(dim)  # validates dim
    return HamiltonPoisson(Partial(_canonical_pi, dim), hamiltonian, (), name)


def _constant_pi(matrix, x):
    return jnp.asarray(matrix, dtype=x.dtype)


def constant_poisson_system(matrix, hamiltonian: Callable, name: str = "constant-poisson") -> HamiltonPoisson:
    """(Rⁿ, Π, H) with a constant skew matrix Π (any constant skew matrix is Poisson).

    >>> import jax.numpy as jnp, jaxsplit
    >>> system = jaxsplit.constant_poisson_system(jnp.array([[0.0, 1.0], [-1.0, 0.0]]), lambda x: 0.5 * x @ x)
    >>> system.vector_field(jnp.array([1.0, 0.0]))
    Array([ 0., -1.], dtype=float64)"""
    mat = np.asarray(matrix, dtype=float)
    if mat.ndim != 2 or mat.shape[0] != mat.shape[1] or not np.allclose(mat, -mat.T, rtol=0, atol=1e-14):
        raise InputError(f"a constant Poisson matrix must be square and skew, got {mat.tolist()}")
    return HamiltonPoisson(Partial(_constant_pi, jnp.asarray(mat)), hamiltonian, (), name)


def _oscillator_energy(x):
    return 0.5 * (x[0] ** 2 + x[1] ** 2)


def harmonic_oscillator() -> HamiltonPoisson:
    """Example 2.1: x = (q, p), H = ½(q² + p²), ω = dp ∧ dq, q̇ = p, ṗ = −q.

    >>> import jax.numpy as jnp, jaxsplit
    >>> oscillator = jaxsplit.harmonic_oscillator()
    >>> x = jaxsplit.integrate(jaxsplit.gauss_legendre(oscillator, 2), jnp.array([1.0, 0.0]), 0.1, 10).final
    >>> x                                          # ≈ (cos 1, −sin 1)
    Array([ 0.54030242, -0.84147091], dtype=float64)
    >>> float(abs(oscillator.hamiltonian(x) - 0.5)) < 1e-15
    True"""
    return canonical_system(_oscillator_energy, 2, "harmonic-oscillator")


# ---------------------------------------------------------------- Example 3.1
def _ex31_pi(x):
    z = jnp.zeros_like(x[1])
    return jnp.stack([jnp.stack([z, x[1]]), jnp.stack([-x[1], z])])


def _ex31_energy(coefficients, x):
    a, b, c = coefficients
    return a * x[0] + b * x[1] + c


def example_3_1(a=1.0, b=1.0, c=0.0) -> HamiltonPoisson:
    """Example 3.1: Π(x) = [[0, x₂], [−x₂, 0]], H = A x₁ + B x₂ + C, ẋ = (B x₂, −A x₂).

    >>> import jax.numpy as jnp, jaxsplit
    >>> jaxsplit.example_3_1(1.0, 2.0).vector_field(jnp.array([0.5, 1.0]))
    Array([ 2., -1.], dtype=float64)"""
    coefficients = jnp.stack([jnp.asarray(a), jnp.asarray(b), jnp.asarray(c)]).astype(jnp.result_type(float))
    if not isinstance(coefficients, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(coefficients))):
        raise InputError(f"A, B, C must be finite, got {(a, b, c)}")
    return HamiltonPoisson(_ex31_pi, Partial(_ex31_energy, coefficients), (), "example-3.1")
