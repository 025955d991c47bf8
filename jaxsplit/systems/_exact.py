"""The exact solution of the free rigid body for any inertia: m(t) by Jacobi elliptic
functions, the attitude Q(t) by an elliptic integral of the third kind.

ṁ = m × Wm with W = diag(1/I) (the repo's sign), G² = |m|², 2E = ⟨m, Wm⟩.

**One normal form.** A proper rotation F (axes sorted by increasing 1/I, one sign flipped if
the sort is odd) gives weights v_1 <= v_2 <= v_3 and the same equations, since
F(a × b) = Fa × Fb. With D_1 = 2E − v_1G² = (v_2−v_1)m_2² + (v_3−v_1)m_3²,
D_3 = v_3G² − 2E = (v_3−v_1)m_1² + (v_3−v_2)m_2² (sums of squares: no cancellation) and
D_2 = 2E − v_2G² = (v_3−v_2)m_3² − (v_2−v_1)m_1², the orbit circles the minor axis (largest
1/I) when D_2 >= 0 and the major axis when D_2 < 0. The second family is mapped onto the
first: the proper rotation (e_3, −e_2, e_1) swaps the axes, the weights v ↦ v_1 + v_3 − v
reverse their order (adding the Casimir multiple (v_1 + v_3)|m|²/2 changes no trajectory)
and negate the field, so time runs backwards. Then for D_2 >= 0, with amplitudes
A_1² = D_3/(v_3−v_1), A_2² = D_3/(v_3−v_2), A_3² = D_1/(v_3−v_1),

    m(t) = (σ_1 A_1 cn τ, A_2 sn τ, σ_3 A_3 dn τ),   τ = τ_0 + λt,   λ = −σ_1σ_3 √(D_1 (v_3−v_2)),
    k² = (v_2−v_1) D_3 / ((v_3−v_2) D_1),   k'² = (v_3−v_1) D_2 / ((v_3−v_2) D_1),

σ_1, σ_3 the signs of m_1(0), m_3(0) (m_3 never changes sign; choosing σ_1 so too puts the
initial amplitude in [−π/2, π/2], which also covers the separatrix k = 1, where m_1 keeps
its sign). The initial phase is the incomplete integral F(φ_0|k) with sin, cos, Δ of φ_0
read off m(0) directly: τ_0 = s_0 R_F(c_0², d_0², 1), s_0 = m_2/A_2, c_0 = |m_1|/A_1,
d_0 = |m_3|/A_3 (Carlson), so no inverse function is needed. k'² is computed from D_2, so
the modulus is exact to round-off even as k → 1.

**Attitude.** Q (body to space) obeys Q̇ = Q hat(Wm) and keeps L = Qm. In the normal form's
coordinates let M(m) be the rotation with rows (n × e_3/ρ, n × (n × e_3)/ρ, n), n = m/G,
ρ = |n × e_3| (> 0 on every orbit around e_3). Then Q(t) = C Rz(φ(t)) M(m(t)) F with
C = Q_0 Fᵀ M(m_0)ᵀ, and the precession angle about L (Landau–Lifshitz §37) obeys
φ̇ = G(2E − w m_3²)/(G² − m_3²), w the physical 1/I of the circled axis. With
G² − m_3² = A_1²(1 + ν sn²τ), ν = (v_2−v_1)/(v_3−v_2), and in either family

    φ(t) = G w t − G (v_3 − v_1) [Π(−ν; am τ(t)) − Π(−ν; am τ_0)] / λ,

Π the incomplete integral of the third kind (Carlson R_F, R_J), unwrapped over half periods.

Equilibria (m along a principal axis, in a plane of equal moments, or m = 0: D_1 D_3 = 0,
v_2 = v_3, or m_1 = m_3 = 0) are steady rotations, m(t) = m_0 and Q(t) = Q_0 exp(t hat(Wm_0));
the elliptic branch then runs on a safe placeholder so that nothing is NaN.

On the separatrix (k'² = 0: D_2 = 0 exactly) K = ∞, τ is not reduced, and sn, cn, dn are
tanh, sech, sech: m_1, m_3 decay like sech τ and m_2 → ±A_2 = ±G (the saddle) as t → ±∞.

Accuracy (float64, against mpmath at 30 digits, ``tests/test_exact_solution.py``): ~1e-15
relative to |m| for moderate τ, growing like ε·|τ|; near the separatrix the problem itself
grows ill-conditioned (the period grows like log(1/k')), and the error stays below what one
rounding of each input causes (``benchmarks/results/exact_conditioning.md``: at most 0.17 of it,
e.g. 4e-9 at k² = 1 − 1e-8, t = 10³). On the separatrix itself: ≤ 1e-13 (five states, exact
in binary).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._state import host_values
from ._attitude import Attitude
from ._elliptic import incomplete_pi, jacobi_reduced, legendre_integrals, safe_sqrt
from ._rigid_body import as_body, as_float_array, check_inertia, is_concrete
from ._spin import exp_hat
from .so3 import check_shape

_SWAP = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # (e_3, −e_2, e_1): proper


class Orbit(NamedTuple):
    """The constants of one orbit in the normal form (see the module docstring)."""

    frame: jax.Array  # F (3, 3): m_normal = F m
    direction: jax.Array  # +1, or −1 when time runs backwards (the major-axis family)
    amplitudes: jax.Array  # (σ_1 A_1, A_2, σ_3 A_3)
    k2: jax.Array
    kp2: jax.Array
    big_k: jax.Array  # K(k)
    rate: jax.Array  # λ
    tau0: jax.Array
    pi0: jax.Array  # Π(−ν; am τ_0)
    nu: jax.Array
    complete_pi: jax.Array  # Π(−ν | k)
    start: jax.Array  # m_0 in the normal form (a placeholder when steady)
    precession: jax.Array  # (G w, G (v_3 − v_1)): φ = G w t − G (v_3 − v_1) ΔΠ / λ
    steady: jax.Array  # bool: an equilibrium
    omega: jax.Array  # W m_0 (the steady rotation's angular velocity)
    m0: jax.Array


def _proper_sort(w):
    """(F, sorted w): F has rows e_order with one sign flipped for an odd permutation."""
    order = jnp.argsort(w)
    perm = jnp.eye(3, dtype=w.dtype)[order]
    parity = jnp.sign((order[1] - order[0]) * (order[2] - order[0]) * (order[2] - order[1])).astype(w.dtype)
    return perm * jnp.stack([jnp.ones_like(parity), parity, jnp.ones_like(parity)])[:, None], w[order]


def orbit(inertia, m0) -> Orbit:
    """The orbit constants of the free body ``inertia`` (3,) through ``m0`` (3,)."""
    w = 1 / inertia
    sort, u = _proper_sort(w)
    ms = sort @ m0
    d2 = (u[2] - u[1]) * ms[2] ** 2 - (u[1] - u[0]) * ms[0] ** 2
    minor = d2 >= 0
    swap = jnp.asarray(_SWAP, dtype=m0.dtype)
    frame = jnp.where(minor, sort, swap @ sort)
    v = jnp.where(minor, u, jnp.stack([u[0], u[0] + u[2] - u[1], u[2]]))
    m = frame @ m0
    d1 = (v[1] - v[0]) * m[1] ** 2 + (v[2] - v[0]) * m[2] ** 2
    d3 = (v[2] - v[0]) * m[0] ** 2 + (v[2] - v[1]) * m[1] ** 2
    steady = (d1 == 0) | (d3 == 0) | (v[2] == v[1]) | ((m[0] == 0) & (m[2] == 0))
    # the elliptic branch on a placeholder orbit where the state is steady (finite gradients)
    v = jnp.where(steady, jnp.asarray([1.0, 2.0, 3.0], m0.dtype), v)
    m = jnp.where(steady, jnp.asarray([0.3, 0.4, 0.8], m0.dtype), m)
    d1 = (v[1] - v[0]) * m[1] ** 2 + (v[2] - v[0]) * m[2] ** 2
    d2 = (v[2] - v[1]) * m[2] ** 2 - (v[1] - v[0]) * m[0] ** 2
    d3 = (v[2] - v[0]) * m[0] ** 2 + (v[2] - v[1]) * m[1] ** 2
    a1, a2, a3 = jnp.sqrt(d3 / (v[2] - v[0])), jnp.sqrt(d3 / (v[2] - v[1])), jnp.sqrt(d1 / (v[2] - v[0]))
    k2 = (v[1] - v[0]) * d3 / ((v[2] - v[1]) * d1)
    kp2 = jnp.maximum((v[2] - v[0]) * d2 / ((v[2] - v[1]) * d1), 0.0)
    s1 = jnp.where(m[0] >= 0, 1.0, -1.0).astype(m0.dtype)
    s3 = jnp.where(m[2] >= 0, 1.0, -1.0).astype(m0.dtype)
    s0, c0, d0 = jnp.clip(m[1] / a2, -1.0, 1.0), jnp.abs(m[0]) / a1, jnp.abs(m[2]) / a3
    nu = (v[1] - v[0]) / (v[2] - v[1])
    g = safe_sqrt(jnp.sum(m0 * m0))
    w_circled = jnp.where(minor, u[2], u[0])
    tau0, pi0, big_k, complete = legendre_integrals(-nu, s0, c0, d0, kp2)
    return Orbit(frame, jnp.where(minor, 1.0, -1.0).astype(m0.dtype), jnp.stack([s1 * a1, a2, s3 * a3]),
                 k2, kp2, big_k, -s1 * s3 * jnp.sqrt(d1 * (v[2] - v[1])), tau0, pi0, nu, complete, m,
                 jnp.stack([g * w_circled, g * (v[2] - v[0])]), steady, w * m0, m0)


def _frame_about_e3(m):
    """M(m): rows (n × e_3/ρ, n × (n × e_3)/ρ, n), n = m/|m| (..., 3, 3)."""
    n = m / jnp.linalg.norm(m, axis=-1, keepdims=True)
    e3 = jnp.zeros_like(n).at[..., 2].set(1.0)
    r0 = jnp.cross(n, e3)
    r0 = r0 / jnp.linalg.norm(r0, axis=-1, keepdims=True)
    return jnp.stack([r0, jnp.cross(n, r0), n], axis=-2)


def _rotation_z(phi):
    c, s = jnp.cos(phi), jnp.sin(phi)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([c, -s, z], -1), jnp.stack([s, c, z], -1), jnp.stack([z, z, o], -1)], -2)


def _momentum_at(o: Orbit, t):
    """m(t) in the normal form's coordinates, and what the attitude needs of τ."""
    tau = o.tau0 + o.rate * o.direction * t
    sn, cn, dn, turns = jacobi_reduced(tau, o.k2, o.kp2, o.big_k)
    sign = 1 - 2 * jnp.mod(turns, 2)
    m = o.amplitudes * jnp.stack([sign * cn, sign * sn, dn], axis=-1)
    return m, (sn, cn, dn, turns)


def momentum_at(o: Orbit, t):
    """m(t) for times ``t`` (any shape): shape t.shape + (3,)."""
    m, _ = _momentum_at(o, t)
    return jnp.where(o.steady, o.m0, m @ o.frame)  # Fᵀ m_normal, row-wise


def attitude_at(o: Orbit, q0, t):
    """(m(t), Q(t)) for times ``t`` (any shape) from the attitude ``q0`` (3, 3) at t = 0."""
    m, (sn, cn, dn, turns) = _momentum_at(o, t)
    pi = incomplete_pi(-o.nu, sn, cn, dn, turns, o.complete_pi)
    phi = o.precession[0] * t - o.precession[1] * (pi - o.pi0) / o.rate
    c = q0 @ o.frame.T @ jnp.swapaxes(_frame_about_e3(o.start), -1, -2)
    q = c @ _rotation_z(phi) @ _frame_about_e3(m) @ o.frame
    steady_q = q0 @ exp_hat(t[..., None] * o.omega)
    steady = o.steady
    return (jnp.where(steady, o.m0, m @ o.frame), jnp.where(steady, steady_q, q))


def exact_solution(body, x0, t):
    """The exact state of the free rigid body at times ``t`` from ``x0`` at t = 0.

    ``body`` is a ``RigidBody``, an ``attitude`` system or principal moments (3,); ``x0`` is
    m0 (3,), or (m0, Q0) with Q0 ∈ SO(3) (3, 3) body to space. Returns m(t) of shape
    t.shape + (3,), or (m(t), Q(t)) with Q(t) of shape t.shape + (3, 3). Any positive moments
    (the Jacobi elliptic solution, see the module docstring): bare moments must be a physical
    body, a non-physical one is passed built with ``allow_nonphysical=True``. One evaluation
    per output time, its cost independent of t. Plain JAX: ``jit``, ``vmap`` over bodies,
    states and times, and ``grad`` with respect to the inertia and the initial state work. A
    quaternion attitude: compare rotation matrices (``quaternion_to_matrix``), the sign of
    q(t) is the integrator's.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2 / 3]), allow_nonphysical=True)  # 1 + 2/3 < 2
    >>> m0 = jnp.array([0.4, -0.3, 0.8])
    >>> m = jaxsplit.exact_solution(body, m0, jnp.array([0.0, 1.0, 10.0]))   # one evaluation per time
    >>> m
    Array([[ 0.4       , -0.3       ,  0.8       ],
           [ 0.23342137, -0.54866103,  0.73108518],
           [ 0.39690723,  0.30810599,  0.79845811]], dtype=float64)
    >>> step = jaxsplit.roll(jaxsplit.splitting(body, "kahan-li-8"))  # compiles fast
    >>> m10 = jaxsplit.integrate(step, m0, 0.01, 1000).final
    >>> float(jnp.max(jnp.abs(m10 - m[2]))) < 1e-13                   # m(10) against Kahan–Li 8
    True
    """
    # a system's moments were checked when it was built (a non-physical body by request)
    inertia = check_inertia(body.inertia, allow_nonphysical=True) if hasattr(body, "inertia") else as_body(body).inertia
    if inertia.shape != (3,):
        raise InputError(f"exact_solution takes one body, inertia of shape (3,), got {tuple(inertia.shape)} "
                         "(jax.vmap over bodies)")
    attitude = isinstance(x0, tuple)
    if attitude:
        if len(x0) != 2:
            raise InputError(f"x0 must be m0 (3,) or (m0, Q0) with Q0 (3, 3), got a tuple of {len(x0)} parts")
        m0, q0 = as_float_array(x0[0], "m0"), as_float_array(x0[1], "Q0")
        if q0.shape != (3, 3):
            raise InputError(f"Q0 must be a rotation matrix of shape (3, 3), got {tuple(q0.shape)} (a quaternion "
                             "attitude: pass quaternion_to_matrix(q0))")
    else:
        m0 = as_float_array(x0, "m0")
    check_shape(m0, "momentum")
    if m0.shape != (3,):
        raise InputError(f"exact_solution takes one state, m0 of shape (3,), got {tuple(m0.shape)} (jax.vmap over "
                         "states)")
    if attitude:
        Attitude(inertia, allow_nonphysical=True).check_state((m0, q0))  # inertia checked above
    t = jnp.asarray(t, dtype=m0.dtype)
    if is_concrete(t) and not np.all(np.isfinite(host_values(t))):
        raise InputError("t must be finite times")
    inertia = jnp.asarray(inertia, m0.dtype)
    if attitude:
        return _attitude_solution(inertia, m0, q0.astype(m0.dtype), t)
    return _momentum_solution(inertia, m0, t)


# The jit boundary (as ``integrate``): compiled once per shape and dtype, so eager calls are
# cheap; inside a caller's jit / vmap / grad it is simply inlined.
@jax.jit
def _momentum_solution(inertia, m0, t):
    return momentum_at(orbit(inertia, m0), t)


@jax.jit
def _attitude_solution(inertia, m0, q0, t):
    return attitude_at(orbit(inertia, m0), q0, t)
