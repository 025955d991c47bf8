"""The so(3) toolkit the spinning-body systems are built from.

Convention (the seed paper's, and the one of every rotation here):

    R_k(θ) = exp(−θ hat(e_k)),   rotate(x, k, θ) = R_k(θ) x,

so ``rotate`` turns x by −θ about body axis k (clockwise seen from the tip of e_k); for
k = 0, 1, 2 the matrices are the paper's M, N, P. This is the exact flow of
H = ½ c m_k² on so(3)* with ṁ = m × ∇H = −θ̇ hat(e_k) m, θ = c m_k t, and m_k is
invariant. About a unit vector n, ``rotate_about(x, n, θ) = exp(−θ hat(n)) x`` (Rodrigues),
the flow of ½ c ⟨n, m⟩². ``hat(v) w = v × w``; for the free body hat(m) = Π(m).

A rotation flow turns the *declared parts* of a state with m. A state is either m itself
(an array (..., 3)) or a tuple (or NamedTuple) whose parts are named by ``parts``:

* ``"momentum"`` — m, whose component gives the angle (exactly one part);
* ``"vector"`` — a body-frame vector that turns like m (Γ of the heavy top, a passive
  vector, Kirchhoff's linear momentum): v ← R v;
* ``"attitude"`` — Q ∈ SO(3), body to space, shape (..., 3, 3): Q̇ = Q hat(∇_m H) gives
  Q ← Q Rᵀ (each row of Q turns like a body vector), so the spatial momentum Q m is kept;
* ``"quaternion"`` — the same attitude as a unit quaternion q = (w, x, y, z), scalar first:
  q ← q ⊗ r with r = (cos θ/2, sin θ/2 n) the quaternion of Rᵀ (unit norm kept);
* ``"fixed"`` — left as it is (a parameter carried in the state, a counter).

Rotations act on the last axis and broadcast over leading axes: ``x[..., k]``.

The kernel (``cos_sin``). XLA's ``sin`` and ``cos`` reduce the angle's range and are
evaluated separately: they dominate the cost of a rotation. A rotation's angle is bounded in
advance whenever every flow of a step rotates m (then |m| is conserved, so |θ| <=
|c|·|m0|·|t| for every sub-step t of the run): for |θ| <= L the ``"polynomial"`` kernel
evaluates polynomials of cos θ and sin θ / θ in the shared θ², with no range reduction, each
the shortest whose error on |θ| <= L is below a quarter of the dtype's epsilon
(``_polynomials``: the Taylor series economized in Chebyshev polynomials, in exact
arithmetic; 1–3 terms fewer in all than the truncated Taylor series at the same bound, 3–21 %
less time per rotation in a batch, ``benchmarks/kernel.py``). Accurate to round-off:
measured ≤ 0.5 ulp, cos² + sin² − 1 ≤ 2 ulp, in ``tests/test_kernel.py``. The smaller the
bound, the fewer the terms (float64: 8 for L = 1/16, 16 for L = 1), so L is the smallest of
``POLYNOMIAL_LIMITS`` above the run's bound (``angle_limit``), and an entry of a composition's
word with a smaller weight takes the smaller L its own bound allows (``lower_limits``,
``for_weight``); a rotation evaluates the half angle (``half_cos_sin``), so its polynomial is
truncated for L/2. The map is the same exact
rotation; only its trigonometry is evaluated differently. ``for_run`` selects the kernel
once per run from the initial state (``Composition.for_run``, called by ``integrate``); the
``"general"`` kernel is used otherwise. For a batch of free-body states a run also picks the
layout (``COMPONENTS_FIRST_UP_TO``): components first (structure of arrays: each component
contiguous over the batch, ``components_first``), or components last with each rotation a
select on the component index that evaluates the polynomial once per state
(``_with_components``).
"""

import dataclasses
import functools
import math
from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core._compose import Composition, entries_of, reach_of
from ..core._errors import InputError
from ..core._flows import AbstractFlow
from ..core._loops import selects
from ..core._memo import derived
from ..core._state import fits_batch

PARTS = ("momentum", "vector", "attitude", "quaternion", "fixed")


def hat(v):
    """hat(v) w = v × w, shape (..., 3, 3); for the rigid body this is the Poisson matrix Π(m).

    >>> import jax.numpy as jnp, jaxsplit
    >>> jaxsplit.hat(jnp.array([1.0, 2.0, 3.0])) @ jnp.array([0.0, 0.0, 1.0])   # (1, 2, 3) × e_3
    Array([ 2., -1.,  0.], dtype=float64)
    """
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack(
        [
            jnp.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            jnp.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            jnp.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


KERNELS = ("general", "polynomial")
# |θ| (rad) bounds with their own truncation; the largest is where the polynomial kernel stops
# being cheaper than XLA's cos and sin for one state (benchmarks/kernel.py)
POLYNOMIAL_LIMITS = (0.125, 0.25, 0.5, 1.0)
POLYNOMIAL_LIMIT = POLYNOMIAL_LIMITS[-1]


def _chebyshev_polynomials(n: int) -> list[list[int]]:
    """T_0 … T_n as integer monomial coefficients (T_{k+1} = 2 t T_k − T_{k−1})."""
    out = [[1], [0, 1]]
    while len(out) <= n:
        doubled = [0] + [2 * a for a in out[-1]]
        out.append([a - b for a, b in zip(doubled, out[-2] + [0, 0])])
    return out[: n + 1]


def _economized(offset: int, limit: float, tolerance: float, degree: int = 14) -> tuple[float, ...]:
    """Coefficients in z = θ² of cos θ (``offset`` 0) or sin θ / θ (1) on |θ| <= ``limit``, as few
    as keep the error below ``tolerance``: the Taylor series to ``degree`` (its remainder bounded
    by the first omitted term, the series alternating and decreasing), re-expanded in Chebyshev
    polynomials of z over [0, limit²], whose top terms are dropped while their summed
    coefficients (|T_k| <= 1 there) and the remainder stay below ``tolerance``. In exact
    rational arithmetic; only the kept coefficients are rounded."""
    z_max = Fraction(limit) ** 2
    taylor = [Fraction((-1) ** k, math.factorial(2 * k + offset)) for k in range(degree + 1)]
    error = z_max ** (degree + 1) / math.factorial(2 * degree + 2 + offset)
    # z = z_max (t + 1) / 2, t in [−1, 1]: monomials in t, then Chebyshev coefficients (top down)
    in_t = [sum(a * (z_max / 2) ** k * math.comb(k, j) for k, a in enumerate(taylor) if k >= j)
            for j in range(degree + 1)]
    chebyshev = _chebyshev_polynomials(degree)
    weights = [Fraction(0)] * (degree + 1)
    for n in range(degree, -1, -1):
        weights[n] = in_t[n] / chebyshev[n][n]
        for j, a in enumerate(chebyshev[n]):
            in_t[j] -= weights[n] * a
    kept = degree
    while kept and error + abs(weights[kept]) <= tolerance:
        error += abs(weights[kept])
        kept -= 1
    in_t = [sum(weights[k] * chebyshev[k][j] for k in range(j, kept + 1)) for j in range(kept + 1)]
    # back to z: t = 2 z / z_max − 1
    in_z = [sum(a * math.comb(k, j) * (2 / z_max) ** j * (-1) ** (k - j) for k, a in enumerate(in_t) if k >= j)
            for j in range(kept + 1)]
    return tuple(float(a) for a in in_z)


@functools.cache
def _polynomials(dtype_name: str, limit: float = POLYNOMIAL_LIMIT) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Coefficients in θ² of cos θ and sin θ / θ for |θ| <= ``limit``, each the shortest whose
    error there is below a quarter of the dtype's epsilon (``_economized``; float64: 8 terms in
    all at |θ| <= 1/16 and 16 at 1, where the truncated Taylor series needs 10 and 19)."""
    tolerance = float(np.finfo(dtype_name).eps) / 4
    return _economized(0, limit, tolerance), _economized(1, limit, tolerance)


def _horner(coefficients, x):
    acc = coefficients[-1]
    for a in coefficients[-2::-1]:
        acc = acc * x + a
    return acc


def cos_sin(angle, kernel: str = "general", limit: float = POLYNOMIAL_LIMIT, shared: bool = False):
    """(cos θ, sin θ): the one place every rotation evaluates its trigonometry.

    ``kernel="general"``: XLA's cos and sin (any angle). ``"polynomial"``: for |θ| <= ``limit``
    only (the caller guarantees it), polynomials in the shared θ² (``_polynomials``) accurate
    to round-off there (see the module docstring). ``shared``: the pair feeds
    several turned vectors (a state's parts, a state and its cotangent), so a scalar angle's
    XLA cos and sin are evaluated once too (``_evaluated_once``; a batch's always are).
    """
    angle = jnp.asarray(angle)
    if kernel == "polynomial":
        cos_c, sin_c = _polynomials(np.dtype(angle.dtype).name, float(limit))
        square = angle * angle
        return _horner(cos_c, square), angle * _horner(sin_c, square)
    pair = jnp.cos(angle), jnp.sin(angle)
    return _evaluated_once(*pair) if angle.ndim or shared else pair


@jax.custom_jvp
def _evaluated_once(c, s):
    """(c, s) unchanged, but computed in a kernel of their own, once per angle.

    Why: XLA's CPU fusion puts cos and sin inside every elementwise kernel that consumes them
    and evaluates them again for each element it writes (2 per rotated vector and angle;
    the reversible adjoint turns the state and its cotangent): 10³ heavy tops, 4 vectors
    turned per angle, 160 ns per body and rotation instead of 40 (profiled). An
    ``optimization_barrier`` does not prevent it; a reduction is never fused into its
    elementwise consumers, so the pair goes through an exact one: a sum from −0.0 with a row
    of −0.0 (x + (−0.0) = x for every x, −0.0 and NaN included; ``jnp.sum`` starts from +0.0).
    For XLA's cos and sin of a batch, and of a scalar angle whose pair feeds several kernels
    (``shared``): one kernel per turned vector, each evaluating the pair again (one heavy
    top's reversible gradient: 5 rotations per step, 20 evaluations instead of 5; its
    gradient / forward ran at 3.1×, now 2.2×). A scalar angle feeding one vector is left
    alone (the free body's stored-trajectory gradient ran 15 % slower with it), and so is the
    polynomial kernel: re-evaluating it costs less than the extra pass (free body, 4096
    states: 1.5× slower with it, while XLA's cos and sin run 1.5× faster with it).
    """
    pair = jnp.stack([c, s])
    negative_zero = jnp.asarray(-0.0, pair.dtype)
    pair = jax.lax.reduce(jnp.stack([pair, jnp.full_like(pair, -0.0)]), negative_zero, jax.lax.add, (0,))
    return pair[0], pair[1]


@_evaluated_once.defjvp
def _evaluated_once_jvp(primals, tangents):
    # the identity to differentiation: tangents pass through, no reduction to transpose
    return _evaluated_once(*primals), tangents


def half_cos_sin(angle, kernel: str = "general", limit: float = POLYNOMIAL_LIMIT, shared: bool = False):
    """(cos θ/2, sin θ/2) (by ``cos_sin``'s ``kernel``; for |θ| <= ``limit`` the polynomial is
    truncated for |θ/2| <= ``limit``/2: fewer terms, the same accuracy): every rotation by θ is
    applied from these, as an increment.

    Why: a rounded pair (cos θ, sin θ) has cos² + sin² = 1 + δ with |δ| ~ ε, and the same δ
    every step when the angle is set by a conserved quantity (m_3 of a symmetric body, |m| of a
    spin), so norms drift like n·δ (2e-11 over 10⁵ steps). Written as x + 2 sin(θ/2)(…) (1 − cos θ
    = 2 sin²(θ/2), sin θ = 2 sin(θ/2) cos(θ/2)), the map's defect is 4 sin²(θ/2) δ = O(θ² ε) and
    the rest of the rounding is a random walk.
    """
    return cos_sin(angle / 2, kernel, limit / 2, shared)


def rotation_matrix(axis: int, angle):
    """R_k(θ) = exp(−θ hat(e_k)): the paper's M, N or P for axis 0, 1, 2.

    >>> import jax.numpy as jnp, jaxsplit
    >>> P = jaxsplit.rotation_matrix(2, jnp.pi / 2)            # the paper's P at θ = π/2
    >>> P.round(12)
    Array([[ 0.,  1.,  0.],
           [-1.,  0.,  0.],
           [ 0.,  0.,  1.]], dtype=float64)
    """
    _check_axis(axis)
    c, s = cos_sin(angle)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    rows = {
        0: ((o, z, z), (z, c, s), (z, -s, c)),  # M
        1: ((c, z, -s), (z, o, z), (s, z, c)),  # N
        2: ((c, s, z), (-s, c, z), (z, z, o)),  # P
    }[axis]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def _component(x, k: int, first: bool = False):
    return x[k] if first else x[..., k]


def _with_components(x, new: dict, first: bool = False, select: bool = True):
    """``x`` with the components ``new`` = {k: values} replaced (on its first axis if ``first``,
    else on its last).

    Why two forms: XLA compiles a ``stack`` (a concatenate) as one loop per piece, so what the
    new components share (a rotation's cos and sin) is evaluated once per piece. On the last
    axis a ``select`` on the component index keeps a state's components in one loop iteration,
    where LLVM evaluates the shared part once (a rotation: 16 instead of 26 vector operations per
    8 bodies) and XLA fuses two rotations per kernel; it is used where its constant component
    tests are sure to stay in the kernel, inside jaxsplit's own loops (``core._loops``), and for
    bare m states only (``select``): for a state of parts (a heavy top's m and Γ) its rounding
    differs from the stack's, and the reversible gradient of a Lagrange top over 10⁵ steps
    then agreed with the stored one to 1.1e-9 instead of 3.8e-11. Components first, each
    component is a row of its own: there the stack, which copies the unchanged row, is the
    faster (the layout is chosen per run, ``COMPONENTS_FIRST_UP_TO``)."""
    if first or not (select and selects()):
        axis = 0 if first else -1
        return jnp.stack([new.get(k, _component(x, k, first)) for k in range(x.shape[axis])], axis=axis)
    index = jax.lax.broadcasted_iota(jnp.int32, x.shape, x.ndim - 1)
    for k, value in new.items():
        x = jnp.where(index == k, jnp.expand_dims(value, -1), x)
    return x


def _turn_axis(x, axis: int, c, s, first: bool = False, select: bool = True):
    """R_k x from (cos θ/2, sin θ/2) (``half_cos_sin``), as an increment on the two components it
    changes: x_i + 2 sin(θ/2)(cos(θ/2) x_j − sin(θ/2) x_i), x_j − 2 sin(θ/2)(cos(θ/2) x_i + sin(θ/2) x_j)
    (``first``: the components are on the first axis of ``x`` instead of the last)."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    xi, xj = _component(x, i, first), _component(x, j, first)
    u = s + s
    return _with_components(x, {i: xi + u * (c * xj - s * xi), j: xj - u * (c * xi + s * xj)}, first, select)


def rotate(x, axis: int, angle):
    """R_k(θ) x = ``rotation_matrix(axis, angle) @ x`` on the last axis of ``x``, computed on
    the two components it changes (as fast as hand-fused scalar code).

    >>> import jax.numpy as jnp, jaxsplit
    >>> jaxsplit.rotate(jnp.array([1.0, 0.0, 0.0]), 2, jnp.pi / 2).round(12)
    Array([ 0., -1.,  0.], dtype=float64)
    """
    _check_axis(axis)
    return _turn_axis(x, axis, *half_cos_sin(angle))


def _turn_vector(x, n, c, s):
    """exp(−θ hat(n)) x = x − (n × x) sin θ + n × (n × x) (1 − cos θ) (n a unit vector), from
    (cos θ/2, sin θ/2) as an increment: x − 2 sin(θ/2)(cos(θ/2) n × x − sin(θ/2) n × (n × x))."""
    c, s = c[..., None], s[..., None]
    nx = jnp.cross(n, x)
    return x - (s + s) * (c * nx - s * jnp.cross(n, nx))


def rotate_about(x, direction, angle):
    """exp(−θ hat(n)) x with n = direction/|direction|; ``rotate_about(x, e_k, θ) = rotate(x, k, θ)``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> jaxsplit.rotate_about(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 2.0]), jnp.pi / 2).round(12)
    Array([ 0., -1.,  0.], dtype=float64)
    """
    n = jnp.asarray(direction)
    n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
    return _turn_vector(x, n, *half_cos_sin(jnp.asarray(angle)))


def rotation_matrix_about(direction, angle):
    """exp(−θ hat(n)) as a matrix (Rodrigues), n = direction/|direction|.

    >>> import jax.numpy as jnp, jaxsplit
    >>> R = jaxsplit.rotation_matrix_about(jnp.array([1.0, 2.0, 2.0]), 0.7)
    >>> bool(jnp.allclose(R @ R.T, jnp.eye(3), atol=1e-15)), bool(jnp.allclose(R @ jnp.array([1.0, 2.0, 2.0]), jnp.array([1.0, 2.0, 2.0])))
    (True, True)
    """
    n = jnp.asarray(direction)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=n.dtype), n.shape[:-1] + (3, 3))
    return jnp.swapaxes(rotate_about(eye, n[..., None, :], jnp.asarray(angle)[..., None]), -1, -2)


def quaternion_multiply(p, q):
    """The Hamilton product p ⊗ q of quaternions (w, x, y, z), scalar first.

    >>> import jax.numpy as jnp, jaxsplit
    >>> q = jnp.array([jnp.cos(jnp.pi / 4), 0.0, 0.0, jnp.sin(jnp.pi / 4)])   # a quarter turn about z
    >>> jaxsplit.quaternion_multiply(q, q).round(12)                          # a half turn
    Array([0., 0., 0., 1.], dtype=float64)
    """
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - jnp.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w, v], axis=-1)


def quaternion_to_matrix(q):
    """The rotation matrix of the unit quaternion q = (w, x, y, z) (body to space).

    >>> import jax.numpy as jnp, jaxsplit
    >>> q = jnp.array([jnp.cos(jnp.pi / 4), 0.0, 0.0, jnp.sin(jnp.pi / 4)])
    >>> jaxsplit.quaternion_to_matrix(q).round(12)
    Array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]], dtype=float64)
    """
    w, x, y, z = (q[..., k] for k in range(4))
    return jnp.stack([
        jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def _half_angle_increment(n, angle, kernel: str = "general", limit: float = POLYNOMIAL_LIMIT):
    """r − 1 = 2 sin(θ/4)(−sin(θ/4), cos(θ/4) n) for r = (cos θ/2, sin θ/2 n), the quaternion of
    exp(+θ hat(n)) = Rᵀ: q ⊗ r is applied as q + q ⊗ (r − 1) (see ``half_cos_sin``)."""
    c, s = half_cos_sin(angle / 2, kernel, limit)
    return (s + s)[..., None] * jnp.concatenate([-s[..., None], c[..., None] * n], axis=-1)


def _check_axis(axis):
    if isinstance(axis, bool) or axis not in (0, 1, 2):
        raise InputError(f"axis must be 0, 1 or 2 (axes are counted from 0), got {axis!r}")


def check_parts(parts):
    """``parts`` is None (the state is m) or a tuple of PARTS with exactly one "momentum"."""
    if parts is None:
        return None
    parts = tuple(parts)
    bad = [p for p in parts if p not in PARTS]
    if bad or parts.count("momentum") != 1:
        raise InputError(f"parts must name each part of a tuple state, one of {PARTS}, with exactly one "
                         f"'momentum'; got {parts!r}")
    return parts


def momentum(state, parts):
    """m: the state itself, or its "momentum" part (shapes checked)."""
    if parts is None:
        return check_shape(state, "momentum")
    if not isinstance(state, tuple) or len(state) != len(parts):
        got = (f"a tuple of length {len(state)}" if isinstance(state, tuple) else
               f"an array of shape {tuple(state.shape)}" if hasattr(state, "shape") else type(state).__name__)
        raise InputError(f"the state must be a tuple of {len(parts)} parts {parts}, got {got}")
    return check_shape(state[parts.index("momentum")], "momentum")


_TRAILING = {"momentum": (3,), "vector": (3,), "attitude": (3, 3), "quaternion": (4,)}


def check_shape(leaf, part: str):
    """A part's trailing shape (checked while tracing: shapes are static)."""
    shape = tuple(getattr(leaf, "shape", ()))
    want = _TRAILING.get(part)
    if want is not None and shape[len(shape) - len(want):] != want:
        label = "m" if part == "momentum" else f"the {part} part"
        raise InputError(f"{label} must have shape (..., {', '.join(map(str, want))}), got {shape}")
    return leaf


def _turn_state(state, parts, turn_vector, quaternion):
    """Apply a rotation to every declared part: ``turn_vector(v, extra)`` for m, vectors and
    attitude rows (``extra`` trailing axes to broadcast over), ``quaternion()`` = r − 1 for q ← q ⊗ r."""
    if parts is None:
        return turn_vector(state, 0)
    out = []
    for part, leaf in zip(parts, state):
        check_shape(leaf, part)
        if part in ("momentum", "vector"):
            out.append(turn_vector(leaf, 0))
        elif part == "attitude":
            out.append(turn_vector(leaf, 1))
        elif part == "quaternion":  # q ⊗ r as an increment q + q ⊗ (r − 1), as for vectors
            out.append(leaf + quaternion_multiply(leaf, quaternion()))
        else:
            out.append(leaf)
    return type(state)(*out) if hasattr(state, "_fields") else tuple(out)


def _expand(a, extra: int):
    return a.reshape(a.shape + (1,) * extra)


# The layout of a batch of bare m states (``for_run``). Components last, a rotation replaces two
# components by a select (``_with_components``): one pass over the batch that evaluates the
# polynomial once per state, two rotations per kernel; 1.1–1.3× faster than components first
# for steps of 6 to 26 rotations, 32 to 10⁵ bodies (``benchmarks/layout.py``). Components first
# (a kernel per rotation, each row contiguous) where that loses: a step of one or two rotations
# fuses into one kernel that reads and writes the whole state, which XLA then copies every step
# (the update reads other components, so it cannot be in place): 1.1–1.25× faster components
# first; and angles above 1/4 (polynomials of 11 terms and more) can make a kernel of two
# rotations costly enough for XLA's cost model to split it over two threads, which at a few
# hundred bodies costs more than the kernel (256 bodies, Blanes–Casas–Murua 8, 640 steps: 1.2–1.6×
# slower components last). The angle rule is conservative: at 1250 steps, where most of the
# word's entries take shorter polynomials (``lower_limits``), components last is 1.1× faster.
COMPONENTS_FIRST_UP_TO = 2
COMPONENTS_LAST_UP_TO = POLYNOMIAL_LIMITS[1]


class AbstractRotation(AbstractFlow):
    """A flow that turns m (and the declared parts) by an exact rotation whose angle is
    rate·(a component of m)·t: |m| is conserved, so a step made only of such flows bounds
    every angle of a run in advance (``for_run``). Subclasses declare the static fields
    ``kernel`` and ``angle_limit`` (see ``cos_sin``), ``components_first`` and ``lower_limits``
    (the shorter polynomials of a composition's smaller weights, ``for_weight``)."""

    def __check_init__(self):
        if self.kernel not in KERNELS:
            raise InputError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        if self.angle_limit not in POLYNOMIAL_LIMITS:
            raise InputError(f"angle_limit must be one of {POLYNOMIAL_LIMITS}, got {self.angle_limit!r}")

    def _momentum(self, state):
        if self.components_first:
            if tuple(state.shape[:1]) != (3,):
                raise InputError(f"a components-first state needs shape (3, ...), got {tuple(state.shape)}")
            m = state
        else:
            m = momentum(state, self.parts)
        _check_batch(jnp.shape(self.rate), m.shape[1:] if self.components_first else m.shape[:-1])
        return m

    def check_state(self, x):
        """The declared parts' values (``_validate.check_parts``): an attitude must be a rotation."""
        if self.parts is None or "attitude" not in self.parts and "quaternion" not in self.parts:
            return x  # momenta and body vectors: any vector
        from ._validate import check_parts as check_values  # _validate builds on so3

        return check_values(x, self.parts)

    def for_run(self, x0, t, step):
        """This rotation with the fastest kernel for one run of ``step`` from ``x0`` with
        sub-steps |s| <= ``t`` (concrete values): ``"polynomial"`` where every flow of ``step``
        rotates the same parts (|m| is conserved) and the bound |rate|·max|m0|·t is at most
        ``POLYNOMIAL_LIMIT``, truncated for the smallest of ``POLYNOMIAL_LIMITS`` above the
        bound (``angle_limit``); else ``"general"``. A batch of bare m states gets its
        components first unless the step is longer than ``COMPONENTS_FIRST_UP_TO`` rotations
        and none of its angles exceeds ``COMPONENTS_LAST_UP_TO`` (decided alike by every
        rotation of the step)."""
        flows = getattr(step, "flows", (self,))
        rotations = all(isinstance(f, AbstractRotation) and f.parts == self.parts for f in flows)
        m = _momentum_or_none(x0, self.parts) if rotations else None
        bound = _angle_bound(self.rate, m, t) if m is not None else None
        limit = next((L for L in POLYNOMIAL_LIMITS if bound is not None and bound <= L), POLYNOMIAL_LIMIT)
        kernel = "polynomial" if bound is not None and bound <= POLYNOMIAL_LIMIT else "general"
        first = (m is not None and self.parts is None and all(isinstance(f, AxisRotation) for f in flows)
                 and m.ndim >= 2 and not (getattr(step, "flows_per_step", 1) > COMPONENTS_FIRST_UP_TO
                                          and _largest_angle(self, bound, step) <= COMPONENTS_LAST_UP_TO))
        lower = _lower_limits(self, bound, limit, step) if kernel == "polynomial" else ()
        choice = (kernel, limit, bool(first), lower)
        if choice == (self.kernel, self.angle_limit, self.components_first, self.lower_limits):
            return self
        return derived(self, choice, lambda: dataclasses.replace(self, kernel=kernel, angle_limit=limit,
                                                                  components_first=bool(first), lower_limits=lower))

    def for_weight(self, weight: float):
        """This rotation with its polynomial truncated for the word entry's own angle bound
        (``lower_limits``; ``angle_limit`` covers the largest weight)."""
        limit = dict(self.lower_limits).get(abs(weight), self.angle_limit)
        return self if limit == self.angle_limit else dataclasses.replace(self, angle_limit=limit)


def _lower_limits(rotation, bound, limit, step) -> tuple:
    """((|weight|, limit), ...) for the entries of ``step``'s word that call ``rotation`` with
    a weight whose angle bound (``bound`` scaled by the weight over the largest) lies under a
    smaller one of ``POLYNOMIAL_LIMITS`` than ``limit``: a polynomial shorter by a term or more
    (Blanes–Casas–Murua 8 at h = 0.5 on the standard body: 10 of one piece's 13 rotations).
    Discrete, so a new h or body recompiles only when a choice changes."""
    if not isinstance(step, Composition):
        return ()
    piece = next(k for k, f in enumerate(step.flows) if f is rotation)
    weights = derived(step, ("weights", piece), lambda: _weights_of(entries_of(step), piece))
    out = []
    for w in weights:
        own = next(L for L in POLYNOMIAL_LIMITS if bound * w / weights[-1] <= L or L == limit)
        if own < limit:
            out.append((w, own))
    return tuple(out)


def _weights_of(entries, piece: int) -> tuple[float, ...]:  # remembered per step by ``_lower_limits``
    return tuple(sorted({abs(w) for p, w in entries if p == piece}))


def _largest_angle(rotation, bound, step) -> float:
    """The largest angle bound over ``step``'s rotations, from ``rotation``'s own ``bound``
    (each rotation's bound is |rate|·max|m0|·(its largest weight)·h)."""
    if bound is None or not isinstance(step, Composition):
        return math.inf if bound is None else bound
    scaled = derived(step, "scaled reach", lambda: tuple(w * _largest_rate(f.rate) for f, w in zip(step.flows, reach_of(step))))
    own = next(value for f, value in zip(step.flows, scaled) if f is rotation)
    return bound * max(scaled) / own if own else math.inf


def _largest_rate(rate) -> float:
    return float(np.max(np.abs(np.asarray(rate))))


def _check_batch(parameter_shape, state_batch):
    """A batched body (leading axes on its parameters) needs states with those axes: the state
    is never silently broadcast to several bodies (shapes are static: checked under jit too)."""
    if not fits_batch(parameter_shape, state_batch):
        raise InputError(f"the body's inertia (a rotation's rate) has batch shape {tuple(parameter_shape)} but the "
                         f"state's batch shape is {tuple(state_batch)}: give one state per body, shape "
                         f"{tuple(parameter_shape) + (3,)}, or vmap over the bodies")


def _momentum_or_none(x0, parts):
    """m of a state laid out as ``parts`` declares, or None (a wrong layout is left for the call to refuse)."""
    if parts is not None:
        if not isinstance(x0, tuple) or len(x0) != len(parts):
            return None
        x0 = x0[parts.index("momentum")]
    return x0 if isinstance(x0, jax.Array | np.ndarray) and x0.ndim >= 1 and x0.shape[-1] == 3 else None


def _angle_bound(rate, m, t):
    """max|rate|·max|m|·|t|: a bound on every angle of a run that conserves |m| (None where
    a value is traced)."""
    if any(isinstance(v, jax.core.Tracer) for v in (m, t, rate)):
        return None
    return _largest_rate(rate) * _largest_norm(m) * abs(float(t)) * (1 + 1e-6)


def _largest_norm(m) -> float:
    """max|m| over a batch, reduced where the batch lives: on the CPU by NumPy (a view of the
    array, no dispatch; ``einsum`` without ``linalg.norm``'s temporaries: 81 ms instead of 264
    for 10⁷ bodies), on an accelerator by one device reduction (copying the batch to the host
    and reducing it there, once per flow, made ``for_run`` take 0.93 s for 10⁷ bodies on an H100,
    against a 7.4 ms run of 20 Strang steps; ``benchmarks/results/for_run_cost-gpu.md``)."""
    if isinstance(m, jax.Array) and any(d.platform != "cpu" for d in m.devices()):
        return float(_device_largest_norm(m))
    m = np.asarray(m)
    return float(np.sqrt(np.max(np.einsum("...i,...i->...", m, m))))


@jax.jit
def _device_largest_norm(m):
    return jnp.sqrt(jnp.max(jnp.sum(m * m, axis=-1)))


class AxisRotation(AbstractRotation):
    """Exact flow of H = ½ c m_k²: every declared part turned by R_k(θ), θ = c m_k t.

    ``rate`` = c (an array: traced); ``axis`` = k and ``parts`` (see the module docstring)
    are static, as are ``kernel``, ``angle_limit`` and ``components_first`` (chosen per run
    by ``for_run``).
    A one-parameter group (m_k is invariant).

    >>> import jax.numpy as jnp, jaxsplit
    >>> spin = jaxsplit.AxisRotation(2, jnp.array(0.5), ("momentum", "vector"))   # turns m and Γ together
    >>> m, v = spin((jnp.array([0.6, 0.0, 0.8]), jnp.array([1.0, 0.0, 0.0])), 1.0)   # θ = 0.5 · 0.8 · 1
    >>> m, v
    (Array([ 0.5526366 , -0.23365101,  0.8       ], dtype=float64), Array([ 0.92106099, -0.38941834,  0.        ], dtype=float64))
    >>> spin.is_group
    True
    """

    axis: int = eqx.field(static=True)
    rate: jax.Array = eqx.field(converter=jnp.asarray)
    parts: tuple | None = eqx.field(static=True, default=None, converter=check_parts)
    kernel: str = eqx.field(static=True, default="general")
    angle_limit: float = eqx.field(static=True, default=POLYNOMIAL_LIMIT)
    components_first: bool = eqx.field(static=True, default=False)
    lower_limits: tuple = eqx.field(static=True, default=())

    def __check_init__(self):
        _check_axis(self.axis)

    def angle(self, state, t):
        """θ = m_k · (rate · t): the scalar factor first, so a batch pays one product per state."""
        m = self._momentum(state)
        return _component(m, self.axis, self.components_first) * (self.rate.astype(m.dtype) * t)

    def __call__(self, state, t):
        half = self.angle(state, t / 2)  # θ/2 exactly (halving is exact): ``half_cos_sin`` without its product
        c, s = cos_sin(half, self.kernel, self.angle_limit / 2, shared=_turns_several(self.parts))
        if self.parts is None:  # the free body: the bare two-component update (hot path)
            return _turn_axis(state, self.axis, c, s, self.components_first)
        e = jnp.zeros(3, half.dtype).at[self.axis].set(1)
        return _turn_state(state, self.parts,
                           lambda x, extra: _turn_axis(x, self.axis, _expand(c, extra), _expand(s, extra),
                                                       select=False),
                           lambda: _half_angle_increment(e, half + half, self.kernel, self.angle_limit))

    def step_back(self, x_after, t, ct_after):
        """The inverse rotation and the pullback in one pass, sharing cos and sin: m_k is
        invariant, so θ is the forward angle. With (i, j) the turned pair,
        ct_before = Rᵀ ct_after (= R(−θ), like the state) plus g ∂θ/∂m_k on component k,
        where g = ⟨ct_after, ∂_θ(R x)⟩ = Σ over turned parts of ct_i x_j − ct_j x_i (after)."""
        if self.parts is not None and "quaternion" in self.parts:
            return super().step_back(x_after, t, ct_after)
        first, k = self.components_first, self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        m = self._momentum(x_after)
        m_k = _component(m, k, first)
        rate = self.rate.astype(m.dtype)
        half = self.angle(x_after, t / 2)  # the forward half angle, bit for bit
        c, s = cos_sin(half, self.kernel, self.angle_limit / 2, shared=True)  # state and cotangent

        def back(v, extra):
            return _turn_axis(v, k, _expand(c, extra), -_expand(s, extra), first, select=self.parts is None)

        def torque(v, ct, extra):
            g = _component(ct, i, first) * _component(v, j, first) - _component(ct, j, first) * _component(v, i, first)
            return jnp.sum(g, axis=-1) if extra else g

        if self.parts is None:
            x, ct, g = back(x_after, 0), back(ct_after, 0), torque(x_after, ct_after, 0)
        else:
            x, ct, g = [], [], 0.0
            for part, leaf, ct_leaf in zip(self.parts, x_after, ct_after):
                if part in ("momentum", "vector", "attitude"):
                    extra = int(part == "attitude")
                    x.append(back(leaf, extra))
                    ct.append(back(ct_leaf, extra))
                    g = g + torque(leaf, ct_leaf, extra)
                else:
                    x.append(leaf)
                    ct.append(ct_leaf)
        along = g * rate * t  # θ = rate·m_k·t depends on m_k
        if self.parts is None:
            ct = _add_to_component(ct, k, along, first)
        else:
            at = self.parts.index("momentum")
            ct[at] = _add_to_component(ct[at], k, along, False, select=False)
            rebuild = type(x_after)._make if hasattr(x_after, "_fields") else tuple
            x, ct = rebuild(x), rebuild(ct)
        return x, ct, [g * m_k * t], g * rate * m_k  # per state: summed over a batch once, by the caller


def _turns_several(parts) -> bool:
    """Whether a rotation turns more than one part of the state (its cos and sin are shared)."""
    return parts is not None and sum(p != "fixed" for p in parts) > 1


def _add_to_component(v, k: int, value, first: bool, select: bool = True):
    return _with_components(v, {k: _component(v, k, first) + value}, first, select)


class VectorRotation(AbstractRotation):
    """Exact flow of H = ½ c ⟨n, m⟩² for a unit body vector n: every declared part turned by
    exp(−θ hat(n)), θ = c ⟨n, m⟩ t. ``direction`` (normalised) and ``rate`` are traced.

    >>> import jax.numpy as jnp, jaxsplit
    >>> about_z = jaxsplit.VectorRotation(jnp.array([0.0, 0.0, 1.0]), jnp.array(0.5))
    >>> bool(jnp.allclose(about_z(jnp.array([0.6, 0.0, 0.8]), 1.0),
    ...                   jaxsplit.AxisRotation(2, jnp.array(0.5))(jnp.array([0.6, 0.0, 0.8]), 1.0), atol=1e-15))
    True
    """

    direction: jax.Array = eqx.field(converter=jnp.asarray)
    rate: jax.Array = eqx.field(converter=jnp.asarray)
    parts: tuple | None = eqx.field(static=True, default=None, converter=check_parts)
    kernel: str = eqx.field(static=True, default="general")
    angle_limit: float = eqx.field(static=True, default=POLYNOMIAL_LIMIT)
    components_first: bool = eqx.field(static=True, default=False)  # never set: acts on the last axis
    lower_limits: tuple = eqx.field(static=True, default=())

    def __call__(self, state, t):
        m = self._momentum(state)
        n = self.direction.astype(m.dtype)
        n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
        angle = self.rate.astype(m.dtype) * jnp.sum(n * m, axis=-1) * t
        c, s = half_cos_sin(angle, self.kernel, self.angle_limit)

        def turn(x, extra):
            nn = n.reshape(n.shape[:-1] + (1,) * extra + (3,))
            return _turn_vector(x, nn, _expand(c, extra), _expand(s, extra))

        return _turn_state(state, self.parts, turn,
                           lambda: _half_angle_increment(n, angle, self.kernel, self.angle_limit))
