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
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._errors import InputError
from ..core._flows import AbstractFlow

PARTS = ("momentum", "vector", "attitude", "quaternion", "fixed")


def hat(v):
    """hat(v) w = v × w, shape (..., 3, 3); for the rigid body this is the Poisson matrix Π(m)."""
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack(
        [
            jnp.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            jnp.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            jnp.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


def cos_sin(angle):
    """(cos θ, sin θ): the one place every rotation evaluates its trigonometry."""
    return jnp.cos(angle), jnp.sin(angle)


def half_cos_sin(angle):
    """(cos θ/2, sin θ/2): every rotation by θ is applied from these, as an increment.

    Why: a rounded pair (cos θ, sin θ) has cos² + sin² = 1 + δ with |δ| ~ ε, and the same δ
    every step when the angle is set by a conserved quantity (m_3 of a symmetric body, |m| of a
    spin), so norms drift like n·δ (2e-11 over 10⁵ steps). Written as x + 2 sin(θ/2)(…) (1 − cos θ
    = 2 sin²(θ/2), sin θ = 2 sin(θ/2) cos(θ/2)), the map's defect is 4 sin²(θ/2) δ = O(θ² ε) and
    the rest of the rounding is a random walk.
    """
    return cos_sin(angle / 2)


def rotation_matrix(axis: int, angle):
    """R_k(θ) = exp(−θ hat(e_k)): the paper's M, N or P for axis 0, 1, 2."""
    _check_axis(axis)
    c, s = cos_sin(angle)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    rows = {
        0: ((o, z, z), (z, c, s), (z, -s, c)),  # M
        1: ((c, z, -s), (z, o, z), (s, z, c)),  # N
        2: ((c, s, z), (-s, c, z), (z, z, o)),  # P
    }[axis]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def _turn_axis(x, axis: int, c, s):
    """R_k x from (cos θ/2, sin θ/2) (``half_cos_sin``), as an increment on the two components it
    changes: x_i + 2 sin(θ/2)(cos(θ/2) x_j − sin(θ/2) x_i), x_j − 2 sin(θ/2)(cos(θ/2) x_i + sin(θ/2) x_j)."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    u = s + s
    out = [None, None, None]
    out[axis] = x[..., axis]
    out[i] = x[..., i] + u * (c * x[..., j] - s * x[..., i])
    out[j] = x[..., j] - u * (c * x[..., i] + s * x[..., j])
    return jnp.stack(out, axis=-1)


def rotate(x, axis: int, angle):
    """R_k(θ) x = ``rotation_matrix(axis, angle) @ x`` on the last axis of ``x``, computed on
    the two components it changes (as fast as hand-fused scalar code)."""
    _check_axis(axis)
    return _turn_axis(x, axis, *half_cos_sin(angle))


def _turn_vector(x, n, c, s):
    """exp(−θ hat(n)) x = x − (n × x) sin θ + n × (n × x) (1 − cos θ) (n a unit vector), from
    (cos θ/2, sin θ/2) as an increment: x − 2 sin(θ/2)(cos(θ/2) n × x − sin(θ/2) n × (n × x))."""
    c, s = c[..., None], s[..., None]
    nx = jnp.cross(n, x)
    return x - (s + s) * (c * nx - s * jnp.cross(n, nx))


def rotate_about(x, direction, angle):
    """exp(−θ hat(n)) x with n = direction/|direction|; ``rotate_about(x, e_k, θ) = rotate(x, k, θ)``."""
    n = jnp.asarray(direction)
    n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
    return _turn_vector(x, n, *half_cos_sin(jnp.asarray(angle)))


def rotation_matrix_about(direction, angle):
    """exp(−θ hat(n)) as a matrix (Rodrigues), n = direction/|direction|."""
    n = jnp.asarray(direction)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=n.dtype), n.shape[:-1] + (3, 3))
    return jnp.swapaxes(rotate_about(eye, n[..., None, :], jnp.asarray(angle)[..., None]), -1, -2)


def quaternion_multiply(p, q):
    """The Hamilton product p ⊗ q of quaternions (w, x, y, z), scalar first."""
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - jnp.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w, v], axis=-1)


def quaternion_to_matrix(q):
    """The rotation matrix of the unit quaternion q = (w, x, y, z) (body to space)."""
    w, x, y, z = (q[..., k] for k in range(4))
    return jnp.stack([
        jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def _half_angle_increment(n, angle):
    """r − 1 = 2 sin(θ/4)(−sin(θ/4), cos(θ/4) n) for r = (cos θ/2, sin θ/2 n), the quaternion of
    exp(+θ hat(n)) = Rᵀ: q ⊗ r is applied as q + q ⊗ (r − 1) (see ``half_cos_sin``)."""
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


class AxisRotation(AbstractFlow):
    """Exact flow of H = ½ c m_k²: every declared part turned by R_k(θ), θ = c m_k t.

    ``rate`` = c (an array: traced); ``axis`` = k and ``parts`` (see the module docstring)
    are static. A one-parameter group (m_k is invariant).
    """

    axis: int = eqx.field(static=True)
    rate: jax.Array = eqx.field(converter=jnp.asarray)
    parts: tuple | None = eqx.field(static=True, default=None, converter=check_parts)

    def __check_init__(self):
        _check_axis(self.axis)

    def __call__(self, state, t):
        m = momentum(state, self.parts)
        angle = self.rate.astype(m.dtype) * m[..., self.axis] * t
        c, s = half_cos_sin(angle)
        if self.parts is None:  # the free body: the bare two-component update (hot path)
            return _turn_axis(state, self.axis, c, s)
        e = jnp.zeros(3, m.dtype).at[self.axis].set(1)
        return _turn_state(state, self.parts,
                           lambda x, extra: _turn_axis(x, self.axis, _expand(c, extra), _expand(s, extra)),
                           lambda: _half_angle_increment(e, angle))


class VectorRotation(AbstractFlow):
    """Exact flow of H = ½ c ⟨n, m⟩² for a unit body vector n: every declared part turned by
    exp(−θ hat(n)), θ = c ⟨n, m⟩ t. ``direction`` (normalised) and ``rate`` are traced."""

    direction: jax.Array = eqx.field(converter=jnp.asarray)
    rate: jax.Array = eqx.field(converter=jnp.asarray)
    parts: tuple | None = eqx.field(static=True, default=None, converter=check_parts)

    def __call__(self, state, t):
        m = momentum(state, self.parts)
        n = self.direction.astype(m.dtype)
        n = n / jnp.linalg.norm(n, axis=-1, keepdims=True)
        angle = self.rate.astype(m.dtype) * jnp.sum(n * m, axis=-1) * t
        c, s = half_cos_sin(angle)

        def turn(x, extra):
            nn = n.reshape(n.shape[:-1] + (1,) * extra + (3,))
            return _turn_vector(x, nn, _expand(c, extra), _expand(s, extra))

        return _turn_state(state, self.parts, turn, lambda: _half_angle_increment(n, angle))
