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

The kernel (``half_turn``). XLA's ``sin`` and ``cos`` reduce the angle's range and are
evaluated separately: they dominated the cost of a rotation (40 ns against 2.5–3). Every
rotation here is applied from the half-angle pair ±(cos θ/2, sin θ/2) as an increment
(``half_cos_sin``), and that pair is needed only up to a common sign, so one straight-line
kernel serves every angle: a Cody–Waite reduction modulo π and polynomials of cos and sin/φ
on |r| <= π/2 (the Taylor series economized in Chebyshev polynomials, in exact arithmetic,
to a quarter of the dtype's epsilon). A run of ``integrate`` whose flows are all rotations of
m (|m| kept) also compiles its loop with shorter polynomials and no reduction, for half
angles up to 1/4 (``core._angles.SHORT_LIMITS``), and picks it inside the compiled program from its largest angle
(``core._angles``): the direct call on 256 free bodies 2.1–2.6× faster. Nothing is chosen from values seen at a
call, so a flow compiles to the same program whether ``integrate`` is called directly or
under a user's ``jit``, ``vmap`` or ``grad``; a batch is the leading axes of the state, and
only its last axis (the components) is ever addressed, which is exactly the axis ``vmap``
leaves last.
"""

import functools
import math
import operator
from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core._angles import largest, short_angles
from ..core._errors import InputError
from ..core._flows import AbstractFlow
from ..core._loops import selects
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


# Every rotation's trigonometry is ONE kernel, valid for every angle and the same whether the
# call is the outermost one or sits under a user's ``jit``, ``vmap`` or ``grad`` (nothing is
# chosen from concrete values): a Cody–Waite reduction modulo π, then polynomials of cos and
# sin/φ on |r| <= π/2 (``half_turn``); inside a run with bounded angles, a short polynomial
# (``core._angles``). XLA's own cos and sin cost 40 ns per rotation against
# 2.5–3 for these polynomials (``benchmarks/results/kernel.md``).
_PI = Fraction("3.14159265358979323846264338327950288419716939937510582097494459230781640628620899863")


def _chebyshev_polynomials(n: int) -> list[list[int]]:
    """T_0 … T_n as integer monomial coefficients (T_{k+1} = 2 t T_k − T_{k−1})."""
    out = [[1], [0, 1]]
    while len(out) <= n:
        doubled = [0] + [2 * a for a in out[-1]]
        out.append([a - b for a, b in zip(doubled, out[-2] + [0, 0])])
    return out[: n + 1]


def _economized(offset: int, limit, tolerance: float, degree: int = 22) -> tuple[float, ...]:
    """Coefficients in z = φ² of cos φ (``offset`` 0) or sin φ / φ (1) on |φ| <= ``limit``, as few
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


def _rounded(value: Fraction, bits: int) -> Fraction:
    """``value`` rounded to ``bits`` significant bits."""
    scale = Fraction(2) ** (bits - 1 - math.floor(math.log2(abs(value))))
    return Fraction(round(value * scale)) / scale


# |n| = |round(φ/π)| below 2^k keeps every product n·piece exact (float64: every angle to 10¹²,
# float32: to ~10⁵, past which φ's own rounding exceeds the reduction's error anyway)
EXACT_TURNS = {"float64": 39, "float32": 16}


@functools.cache
def _kernel_constants(dtype_name: str):
    """(π in pieces, 1/π, the reduced range's bound, cos coefficients, sin/φ coefficients) for
    one floating dtype.

    Cody–Waite: every piece but the last carries ``digits − k`` bits (k = ``EXACT_TURNS``), so
    n·piece is exact for |n| < 2^k and each r − n·piece rounds once, with or without a fused
    multiply-add (the three pieces of 32 bits used before relied on the CPU compiler contracting
    them into FMAs: unoptimised, or on a GPU, cos was wrong by 3e7 ulp at φ ~ 1e8); the last
    piece is the rest of π at the dtype's precision, after enough exact pieces that its product's
    error, n·|rest|·eps/2, is below a quarter of eps. r = φ − nπ is then as accurate as φ itself.
    n = round(φ/π) is computed in the dtype, so |r| may exceed π/2 by the rounding of φ/π,
    at most 2^k·eps·π: the polynomials' range (and the clip in ``half_turn``) includes that
    margin, and their error there is below a quarter of the dtype's epsilon."""
    info = np.finfo(dtype_name)
    digits, k = info.nmant + 1, EXACT_TURNS[dtype_name]
    bits = digits - k
    pieces, rest = [], _PI
    while len(pieces) * bits < k + 2:  # then n·(π − Σ pieces) <= 2^k·2^-(k+2)·π·eps
        piece = _rounded(rest, bits)
        pieces.append(piece)
        rest -= piece
    pieces.append(rest)
    tolerance = float(info.eps) / 4
    limit = _PI / 2 + Fraction(2) ** k * Fraction(float(info.eps)) * _PI
    return (tuple(float(p) for p in pieces), float(1 / _PI), float(limit),
            _economized(0, limit, tolerance), _economized(1, limit, tolerance))


@functools.cache
def _short_polynomials(dtype_name: str, limit: Fraction):
    """Coefficients in φ² of cos φ and sin φ / φ on |φ| <= ``limit``, no reduction (float64 at
    1/8: 5 + 5 terms against the general kernel's 9 + 9 and its reduction)."""
    tolerance = float(np.finfo(dtype_name).eps) / 4
    return _economized(0, limit, tolerance), _economized(1, limit, tolerance)


def _plain(*arrays) -> bool:
    """Whether lax's primitives may stand for the operators on ``arrays``: one shape and one
    dtype, none weakly typed, so the operators' promotion and broadcasting would change
    nothing. Each operator on a traced array goes through ``jnp``'s promotion, a nested ``jit``
    of its own: ~70 µs a call against ~25 µs, and these kernels are traced for every rotation
    of every program (a third of the suite's ``jnp`` calls came from ``_horner``)."""
    kinds = [jax.typeof(a) for a in arrays]
    return all(k.shape == kinds[0].shape and k.dtype == kinds[0].dtype and not k.weak_type for k in kinds)


def _arithmetic(*arrays):
    """(add, sub, mul, const) for a kernel on ``arrays``: lax's primitives and constants in
    their dtype where ``_plain``, else the operators and the constants as given. Either way the same
    program, equation for equation."""
    if not _plain(*arrays):
        return operator.add, operator.sub, operator.mul, lambda a: a
    dtype = jax.typeof(arrays[0]).dtype
    return jax.lax.add, jax.lax.sub, jax.lax.mul, lambda a: np.asarray(a, dtype)


def _horner(coefficients, x):
    add, _, mul, const = _arithmetic(x)
    acc = const(coefficients[-1])
    for a in coefficients[-2::-1]:
        acc = add(mul(acc, x), const(a))
    return acc


def half_turn(phi):
    """(c, s) = ±(cos φ, sin φ), ONE sign for both: the trigonometry of every rotation here.

    Rotations by θ = 2φ use only 2sc = sin θ and 2s² = 1 − cos θ (``half_cos_sin``), which the
    common sign leaves unchanged, so φ is reduced modulo π, not 2π: n = round(φ/π),
    r = φ − nπ in Cody–Waite pieces (``_kernel_constants``), then (cos r, r·p(r²)) by
    polynomials in r² accurate to a quarter of the dtype's epsilon on |r| <= π/2, with no
    branch, table or select: the same straight-line code for every angle, batch and
    transformation. Measured in ``tests/test_kernel.py``: within 2 ulp of NumPy's cos and sin
    over |φ| <= 10⁴ (float64 and float32; float64 to 10¹² as well), c² + s² − 1 within 3 ulp at
    every angle. Integer angles are taken as the default float dtype; the result has φ's
    floating dtype. Traced under ``core._angles.short_angles()`` (a run whose angles are
    bounded), the polynomials for that bound, with no reduction: the same accuracy there.
    """
    phi = jnp.asarray(phi)
    if not jnp.issubdtype(phi.dtype, jnp.floating):
        phi = phi.astype(jnp.result_type(float))
    limit = short_angles()
    if limit is not None:  # a run whose angles are bounded by limit (``core._angles``)
        cos_c, sin_c = _short_polynomials(np.dtype(phi.dtype).name, limit)
        z = phi * phi
        return _horner(cos_c, z), phi * _horner(sin_c, z)
    pieces, inverse_pi, bound, cos_c, sin_c = _kernel_constants(np.dtype(phi.dtype).name)
    n = jnp.round(phi * inverse_pi)
    r = phi
    _, sub, mul, const = _arithmetic(phi)
    for piece in pieces:
        r = sub(r, mul(n, const(piece)))
    # where φ's own rounding exceeds π (float32 beyond ~1e7) n is off by a few: r stays in the
    # polynomials' range, so the pair stays a unit pair (the angle was never resolved there)
    r = jnp.clip(r, -bound, bound)
    z = r * r
    return _horner(cos_c, z), r * _horner(sin_c, z)


@jax.custom_jvp
def evaluated_once(c, s):
    """(c, s) unchanged, but computed in a kernel of their own, once per angle: for a pair
    that several vectors share (a heavy top's m and Γ, a state and its cotangent).

    Why: XLA's CPU fusion puts the pair's arithmetic inside every elementwise kernel that
    consumes it and evaluates it again for each element it writes (each new component of each
    turned vector): 256 heavy tops, two vectors turned, 23 ns per body and sub-flow against
    the free body's ~2. An ``optimization_barrier`` does not prevent it; a reduction is never
    fused into its elementwise consumers, so the pair goes through an exact one: a sum from
    −0.0 with a row of −0.0 (x + (−0.0) = x for every x, −0.0 and NaN included). A bare m
    state turned inside jaxsplit's loops needs none: its select form evaluates the pair once.
    """
    pair = jnp.stack([c, s])
    negative_zero = jnp.asarray(-0.0, pair.dtype)
    pair = jax.lax.reduce(jnp.stack([pair, jnp.full_like(pair, -0.0)]), negative_zero, jax.lax.add, (0,))
    return pair[0], pair[1]


@evaluated_once.defjvp
def _evaluated_once_jvp(primals, tangents):
    # the identity to differentiation: tangents pass through, no reduction to transpose
    return evaluated_once(*primals), tangents


def cos_sin(angle):
    """(cos θ, sin θ) for any θ, from ``half_turn(θ/2)``: cos θ = 1 − 2s², sin θ = 2sc (exact signs).

    >>> import jax.numpy as jnp, jaxsplit
    >>> c, s = jaxsplit.systems.so3.cos_sin(jnp.array(2.0))
    >>> bool(abs(c - jnp.cos(2.0)) < 1e-15), bool(abs(s - jnp.sin(2.0)) < 1e-15)
    (True, True)
    """
    c, s = half_turn(jnp.asarray(angle) / 2)
    u = s + s
    return 1 - u * s, u * c


def half_cos_sin(angle):
    """±(cos θ/2, sin θ/2) with one sign (``half_turn``): every rotation by θ is applied from
    these, as an increment.

    Why: a rounded pair (cos θ, sin θ) has cos² + sin² = 1 + δ with |δ| ~ ε, and the same δ
    every step when the angle is set by a conserved quantity (m_3 of a symmetric body, |m| of a
    spin), so norms drift like n·δ (2e-11 over 10⁵ steps). Written as x + 2 sin(θ/2)(…) (1 − cos θ
    = 2 sin²(θ/2), sin θ = 2 sin(θ/2) cos(θ/2)), the map's defect is 4 sin²(θ/2) δ = O(θ² ε) and
    the rest of the rounding is a random walk.
    """
    return half_turn(jnp.asarray(angle) / 2)


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


def _with_components(x, new: dict, select: bool = True):
    """``x`` with the components ``new`` = {k: values} of its last axis replaced.

    Why two forms: XLA compiles a ``stack`` (a concatenate) as one loop per piece, so what the
    new components share (a rotation's cos and sin) is evaluated once per piece. A ``select``
    on the component index keeps a state's components in one loop iteration, where LLVM
    evaluates the shared part once (a rotation: 16 instead of 26 vector operations per 8
    bodies) and XLA fuses two rotations per kernel; it is used where its constant component
    tests are sure to stay in the kernel, inside jaxsplit's own loops (``core._loops``), and for
    bare m states only (``select``): for a state of parts (a heavy top's m and Γ) its rounding
    differs from the stack's, and the reversible gradient of a Lagrange top over 10⁵ steps
    then agreed with the stored one to 1.1e-9 instead of 3.8e-11. Both forms see only the
    state's last axis, so a batch on leading axes and one added by ``vmap`` run the same code."""
    if not (select and selects()):
        return jnp.stack([new.get(k, x[..., k]) for k in range(x.shape[-1])], axis=-1)
    index = jax.lax.broadcasted_iota(jnp.int32, x.shape, x.ndim - 1)
    for k, value in new.items():
        x = jnp.where(index == k, jnp.expand_dims(value, -1), x)
    return x


def _turn_axis(x, axis: int, c, s, select: bool = True):
    """R_k x from ±(cos θ/2, sin θ/2) (``half_cos_sin``), as an increment on the two components
    it changes: x_i + 2 sin(θ/2)(cos(θ/2) x_j − sin(θ/2) x_i), x_j − 2 sin(θ/2)(cos(θ/2) x_i + sin(θ/2) x_j)."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    xi, xj = x[..., i], x[..., j]
    add, sub, mul, _ = _arithmetic(xi, xj, c, s)
    u = add(s, s)
    return _with_components(x, {i: add(xi, mul(u, sub(mul(c, xj), mul(s, xi)))),
                                j: sub(xj, mul(u, add(mul(c, xi), mul(s, xj))))}, select)


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


def _half_angle_increment(n, angle):
    """r − 1 = 2 sin(θ/4)(−sin(θ/4), cos(θ/4) n) for r = (cos θ/2, sin θ/2 n), the quaternion of
    exp(+θ hat(n)) = Rᵀ: q ⊗ r is applied as q + q ⊗ (r − 1) (see ``half_cos_sin``; the
    common sign of ``half_turn`` cancels in these products)."""
    c, s = half_cos_sin(angle / 2)
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


class AbstractRotation(AbstractFlow):
    """A flow that turns m (and the declared parts) by an exact rotation whose angle is
    rate·(a component of m)·t. Its trigonometry is ``half_turn``'s, valid for every angle, so
    the flow is the same program whatever the call's values and transformations."""

    def _momentum(self, state):
        m = momentum(state, self.parts)
        _check_batch(jnp.shape(self.rate), m.shape[:-1])
        return m

    def turn_rate(self, x):
        """max |rate| · max |m|: |θ| <= that · |t| (θ is rate times a component of m, or of m
        along a unit vector), and every rotation of m keeps |m| (``AbstractFlow.turn_rate``)."""
        m = self._momentum(x)
        return largest(self.rate).astype(m.dtype) * largest(jnp.linalg.norm(m, axis=-1))

    def check_state(self, x):
        """The declared parts' values (``_validate.check_parts``): an attitude must be a rotation."""
        if self.parts is None or "attitude" not in self.parts and "quaternion" not in self.parts:
            return x  # momenta and body vectors: any vector
        from ._validate import check_parts as check_values  # _validate builds on so3

        return check_values(x, self.parts)


def _check_batch(parameter_shape, state_batch):
    """A batched body (leading axes on its parameters) needs states with those axes: the state
    is never silently broadcast to several bodies (shapes are static: checked under jit too)."""
    if not fits_batch(parameter_shape, state_batch):
        raise InputError(f"the body's inertia (a rotation's rate) has batch shape {tuple(parameter_shape)} but the "
                         f"state's batch shape is {tuple(state_batch)}: give one state per body, shape "
                         f"{tuple(parameter_shape) + (3,)}, or vmap over the bodies")


class AxisRotation(AbstractRotation):
    """Exact flow of H = ½ c m_k²: every declared part turned by R_k(θ), θ = c m_k t.

    ``rate`` = c (an array: traced); ``axis`` = k and ``parts`` (see the module docstring)
    are static. A one-parameter group (m_k is invariant).

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

    def __check_init__(self):
        _check_axis(self.axis)

    @property
    def uses_selects(self) -> bool:
        return self.parts is None  # a bare m state: ``_with_components``'s select form

    def angle(self, state, t):
        """θ = m_k · (rate · t): the scalar factor first, so a batch pays one product per state."""
        m = self._momentum(state)
        return m[..., self.axis] * (self.rate.astype(m.dtype) * t)

    def __call__(self, state, t):
        half = self.angle(state, t / 2)  # θ/2 exactly (halving is exact): ``half_cos_sin`` without its product
        c, s = half_turn(half)
        if _turns_several(self.parts):
            c, s = evaluated_once(c, s)
        if self.parts is None:  # the free body: the bare two-component update (hot path)
            return _turn_axis(state, self.axis, c, s)
        e = jnp.asarray(np.eye(3)[self.axis], half.dtype)  # a constant (a scatter would keep the loop off one kernel)
        return _turn_state(state, self.parts,
                           lambda x, extra: _turn_axis(x, self.axis, _expand(c, extra), _expand(s, extra),
                                                       select=False),
                           lambda: _half_angle_increment(e, half + half))

    def step_back(self, x_after, t, ct_after):
        """The inverse rotation and the pullback in one pass, sharing cos and sin: m_k is
        invariant, so θ is the forward angle. With (i, j) the turned pair,
        ct_before = Rᵀ ct_after (= R(−θ), like the state) plus g ∂θ/∂m_k on component k,
        where g = ⟨ct_after, ∂_θ(R x)⟩ = Σ over turned parts of ct_i x_j − ct_j x_i (after)."""
        if self.parts is not None and "quaternion" in self.parts:
            return super().step_back(x_after, t, ct_after)
        k = self.axis
        i, j = (k + 1) % 3, (k + 2) % 3
        m = self._momentum(x_after)
        m_k = m[..., k]
        rate = self.rate.astype(m.dtype)
        half = self.angle(x_after, t / 2)  # the forward half angle, bit for bit
        c, s = evaluated_once(*half_turn(half))  # shared by the state and the cotangent

        def back(v, extra):
            return _turn_axis(v, k, _expand(c, extra), -_expand(s, extra), select=self.parts is None)

        def torque(v, ct, extra):
            g = ct[..., i] * v[..., j] - ct[..., j] * v[..., i]
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
            ct = _add_to_component(ct, k, along)
        else:
            at = self.parts.index("momentum")
            ct[at] = _add_to_component(ct[at], k, along, select=False)
            rebuild = type(x_after)._make if hasattr(x_after, "_fields") else tuple
            x, ct = rebuild(x), rebuild(ct)
        return x, ct, [g * m_k * t], g * rate * m_k  # per state: summed over a batch once, by the caller


def _turns_several(parts) -> bool:
    """Whether a rotation turns more than one part of the state (its cos and sin are shared)."""
    return parts is not None and sum(p != "fixed" for p in parts) > 1


def _add_to_component(v, k: int, value, select: bool = True):
    return _with_components(v, {k: v[..., k] + value}, select)


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

    def __call__(self, state, t):
        m = self._momentum(state)
        n = self.direction.astype(m.dtype)
        n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
        angle = self.rate.astype(m.dtype) * jnp.sum(n * m, axis=-1) * t
        c, s = half_cos_sin(angle)
        if _turns_several(self.parts):
            c, s = evaluated_once(c, s)

        def turn(x, extra):
            nn = n.reshape(n.shape[:-1] + (1,) * extra + (3,))
            return _turn_vector(x, nn, _expand(c, extra), _expand(s, extra))

        return _turn_state(state, self.parts, turn,
                           lambda: _half_angle_increment(n, angle))
