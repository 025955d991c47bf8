"""Exact solution of the symmetric free rigid body.

With I_i = I_j (the paper has I1 = I2) the Hamiltonian differs from the Casimir-shifted
one-piece generator ½(1/I_k − 1/I_i) m_k² by a multiple of C, so the exact flow is a single
rotation about the symmetry axis k by the angle (1/I_k − 1/I_i) m_k t. For k = 3 this is
m1(t) = m1 cos ωt + m2 sin ωt, m2(t) = −m1 sin ωt + m2 cos ωt, m3(t) = m3,
ω = (1/I3 − 1/I1) m3, as in ``shared/reference/rigid-body.md``.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ._body import RigidBody, _as_float_array
from ._errors import InputError
from ._splitting import AxisRotation


def symmetry_axis(body: RigidBody) -> int:
    """The 0-based axis k whose two other moments are equal (concrete inertia)."""
    i = np.asarray(body.inertia)
    for k in (2, 0, 1):
        a, b = (x for x in range(3) if x != k)
        if np.isclose(i[a], i[b], rtol=1e-14, atol=0):
            return k
    raise InputError(f"the body is not symmetric (two equal moments needed), got inertia {i.tolist()}")


def symmetric_solution(body: RigidBody, m0, t, axis: int | None = None):
    """m(t) of a symmetric body from m(0) = m0, for scalar or array ``t``.

    ``axis`` (0-based) is the symmetry axis; found from the inertia when ``None``, which
    needs concrete values (inside ``jit``/``vmap`` over bodies give it, e.g. 2 for I1 = I2).
    """
    if not isinstance(body, RigidBody):
        body = RigidBody(body)
    if axis is None:
        if isinstance(body.inertia, jax.core.Tracer):
            raise InputError("symmetric_solution needs axis= when the inertia is traced")
        axis = symmetry_axis(body)
    m0 = _as_float_array(m0, "m0")
    t = jnp.asarray(t, dtype=m0.dtype)
    rotation = AxisRotation(axis, shift=(axis + 1) % 3)
    flat = jax.vmap(lambda s: rotation(m0, s, body))(t.reshape(-1))
    return flat.reshape(t.shape + m0.shape)
