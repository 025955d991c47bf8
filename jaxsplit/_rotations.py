"""Rotations about the body axes: the seed paper's matrices M, N, P.

The Hamiltonian piece H_k = G(m_k) of the free rigid body generates, on so(3)*, a
rotation about body axis k by the angle t G'(m_k); m_k itself is invariant, so the flow
is exact and a one-parameter group: rotating by a then by b about the same axis is
rotating by a + b. With (i, j) the axes following k cyclically the flow is

    m_i <- cos θ m_i + sin θ m_j,     m_j <- -sin θ m_i + cos θ m_j,

which for k = 1, 2, 3 gives exactly the matrices M, N, P of the paper.
"""

import jax.numpy as jnp


def rotation_matrix(axis: int, angle):
    """The 3x3 rotation of the paper (M, N or P for axis 0, 1, 2) by ``angle``."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    rows = {
        0: ((o, z, z), (z, c, s), (z, -s, c)),  # M
        1: ((c, z, -s), (z, o, z), (s, z, c)),  # N
        2: ((c, s, z), (-s, c, z), (z, z, o)),  # P
    }[axis]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def rotate(m, axis: int, angle):
    """``rotation_matrix(axis, angle) @ m`` computed on the two components it changes
    (agrees with the matrix to round-off; as fast as hand-fused scalar code)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out = [None, None, None]
    out[axis] = m[..., axis]
    out[i] = c * m[..., i] + s * m[..., j]
    out[j] = -s * m[..., i] + c * m[..., j]
    return jnp.stack(out, axis=-1)


def hat(v):
    """hat(v) w = v x w; for the rigid body this is the Poisson matrix Π(m)."""
    z = jnp.zeros_like(v[..., 0])
    return jnp.stack(
        [
            jnp.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            jnp.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            jnp.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )
