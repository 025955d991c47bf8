"""The free rigid body as a Lie–Poisson system on so(3)* = R³, its splits and exact solution.

H(m) = ½ Σ m_i²/I_i,  C(m) = ½|m|²,  Π(m) = hat(m),  ṁ = Π(m) ∇H(m) = m × I⁻¹m
(the seed paper's sign convention). The inertia is an array field, so ``jax.vmap`` sweeps
bodies and ``jax.grad`` differentiates through it; concrete values are validated when a
body is built.

Splits (axes are counted from 0, as everywhere in the library):

* ``"axes"`` (the seed paper): H = H_0 + H_1 + H_2 with H_k = m_k²/(2 I_k), three rotations
  about the body axes, each angle θ_k = m_k t / I_k taken from the state the piece acts on.
* ``"casimir"``: C Poisson-commutes with everything, so H − C/I_k has the same flow as H and
  is a sum of TWO rotation generators Σ_{i≠k} ½ (1/I_i − 1/I_k) m_i². ``shift=k`` is the
  axis, or ``"auto"``: the axis with the middle value of 1/I, which minimises |c_a c_b|, the
  size of the leading commutator [H_a, H_b] of the two pieces; for a symmetric body
  (I_0 = I_1) it removes one piece altogether, making every scheme exact. This split is
  specific to so(3)*: on a larger state (attitude, heavy top) C is no Casimir.

``symmetric_solution`` is the exact solution of a symmetric body: with I_i = I_j the flow is
one rotation about the symmetry axis k by the angle (1/I_k − 1/I_i) m_k t.
"""

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._state import host_values
from ._base import AbstractSystem
from .so3 import AxisRotation, check_shape, hat


def is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def as_float_array(x, name: str):
    """An array of a floating dtype: integers are promoted, floats keep their dtype."""
    if isinstance(x, (jax.Array, np.ndarray)) and jnp.issubdtype(x.dtype, jnp.floating):
        return jnp.asarray(x)
    try:
        arr = jnp.asarray(x)
    except (TypeError, ValueError) as err:
        raise InputError(f"{name} must be numeric, got {x!r}") from err
    if not jnp.issubdtype(arr.dtype, jnp.floating):
        if not (jnp.issubdtype(arr.dtype, jnp.integer) or arr.dtype == bool):
            raise InputError(f"{name} must be real numbers, got dtype {arr.dtype}")
        arr = arr.astype(jnp.result_type(float))
    return arr


_TRIANGLE = ((0, 1, 2), (1, 2, 0), (2, 0, 1))  # I_a + I_b >= I_c, axes labelled 1, 2, 3 like I1, I2, I3


def check_moments(values, name: str = "inertia", allow_nonphysical: bool = False,
                  flag: str = "allow_nonphysical=True"):
    """Concrete principal moments (..., 3), the one check of the library and the command line
    (which passes its option names): finite, > 0, each 1/I representable in their dtype, and
    the triangle inequalities I_a + I_b >= I_c of a physical body unless ``allow_nonphysical``
    (the Euler equations hold for any positive moments: the flag says that such a body is
    wanted). A non-physical body is refused with one line naming its moments, the failing
    inequality and ``flag``; the first failing body of a batch is named."""
    values = np.asarray(values)
    shown = ",".join(f"{float(v):g}" for v in values.reshape(-1)[:3]) if values.size == 3 else str(values.tolist())
    if not np.all(np.isfinite(values)):
        raise InputError(f"{name} must be finite, got {shown}")
    if not np.all(values > 0):
        raise InputError(f"{name} must be positive (I1, I2, I3 > 0), got {shown}")
    with np.errstate(over="ignore", divide="ignore"):
        inverse = 1 / values
    if not np.all(np.isfinite(inverse)):
        k = int(np.argmin(np.isfinite(inverse)) % 3)
        raise InputError(f"{name} {shown}: 1/I{k + 1} overflows {values.dtype} (each moment must be at least "
                         f"{1 / np.finfo(values.dtype).max:.2g})")
    if allow_nonphysical:
        return values
    rows = values.reshape(-1, 3)
    for a, b, c in _TRIANGLE:
        bad = rows[:, a] + rows[:, b] < rows[:, c]
        if np.any(bad):
            i = rows[int(np.argmax(bad))]
            where = f" (body {int(np.argmax(bad))} of the batch)" if len(rows) > 1 else ""
            message = (f"{name} {','.join(f'{float(v):g}' for v in i)}{where} is not a physical body: triangle "
                       f"inequality I{a + 1} + I{b + 1} >= I{c + 1} fails ({i[a]:g} + {i[b]:g} < {i[c]:g}); "
                       f"pass {flag} to integrate it anyway")
            raise InputError(message)
    return values


def check_inertia(inertia, name: str = "inertia", allow_nonphysical: bool = False,
                  flag: str = "allow_nonphysical=True"):
    """Principal moments (..., 3): the shape always (it is static, also under ``jit``), the
    values when concrete (``check_moments``: a physical body unless ``allow_nonphysical``)."""
    inertia = as_float_array(inertia, name)
    if inertia.ndim < 1 or inertia.shape[-1] != 3:
        raise InputError(f"{name} must have 3 components (I1, I2, I3), got shape {tuple(inertia.shape)}")
    if is_concrete(inertia):
        check_moments(host_values(inertia), name, allow_nonphysical, flag)
    return inertia


def as_body(body):
    """``body`` itself when a ``RigidBody``, else a ``RigidBody`` of the moments ``body``, which
    must be physical: a non-physical body is passed built, ``RigidBody(..., allow_nonphysical=True)``
    (the functions taking bare moments have no flag of their own; the message says so)."""
    if isinstance(body, RigidBody):
        return body
    inertia = check_inertia(body, flag="RigidBody(inertia, allow_nonphysical=True) instead of bare moments")
    return RigidBody(inertia, allow_nonphysical=True)  # checked above


def shift_axis(inertia, shift="auto") -> int:
    """The Casimir shift axis (0-based) of the moments ``inertia``: ``shift`` itself, or the axis
    of the middle 1/I for "auto" (concrete, one body)."""
    if isinstance(shift, str) and shift == "auto":
        if not is_concrete(inertia):
            raise InputError("shift='auto' needs concrete inertia; inside jit/vmap/grad pass shift=0, 1 or 2")
        if np.ndim(inertia) != 1:
            raise InputError("shift='auto' needs a single body; for a batch pass shift=0, 1 or 2")
        return middle_axis(1 / host_values(inertia, whole=True))  # it decides the split: the same everywhere
    if isinstance(shift, (bool, np.bool_)) or shift not in (0, 1, 2):
        raise InputError(f"shift must be 0, 1, 2 (the axis, counted from 0) or 'auto', got {shift!r}")
    return int(shift)


def flag(value, name: str = "allow_nonphysical") -> bool:
    """A keyword flag: True or False only (a truthy array, string or None is a mistake)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def middle_axis(inverse_inertia) -> int:
    """The axis (0-based) whose 1/I_k is the middle value (concrete, one body)."""
    return int(np.argsort(np.asarray(inverse_inertia), kind="stable")[1])


class RigidBody(AbstractSystem):
    """A free rigid body with principal moments of inertia ``inertia = (I1, I2, I3) > 0``.

    ``inertia`` may carry leading batch axes (shape ``(..., 3)``); the methods act on states
    ``m`` of shape ``(..., 3)``. Concrete moments must satisfy the triangle inequalities of a
    physical body (I1 + I2 >= I3 and its permutations): another body is refused (``InputError``)
    unless ``allow_nonphysical=True`` says it is wanted (the Euler equations hold for any
    positive moments), as the command line's ``--allow-nonphysical``. The seed paper's test body
    (2, 1, 2/3) is such a body: ``STANDARD_CASE.body()`` builds it with the flag.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody(jnp.array([2.0, 1.0, 2 / 3]), allow_nonphysical=True)  # 1 + 2/3 < 2
    >>> m = jnp.array([0.4, -0.3, 0.8])
    >>> round(float(body.hamiltonian(m)), 12), round(float(body.casimir(m)), 12)
    (0.565, 0.445)
    >>> body.vector_field(m)                      # ṁ = m × I⁻¹m
    Array([-0.12, -0.32, -0.06], dtype=float64)
    >>> sorted(body.splits())
    ['axes', 'casimir']
    """

    inertia: jax.Array
    refused_splits: ClassVar[dict[str, str]] = {}

    def __init__(self, inertia, allow_nonphysical: bool = False):
        self.inertia = check_inertia(inertia, allow_nonphysical=flag(allow_nonphysical))

    def _inverse_inertia(self, m):
        # Computation follows the state's dtype (float32 in -> float32 out).
        check_shape(m, "momentum")
        return 1 / jnp.asarray(self.inertia, dtype=jnp.result_type(m))

    def hamiltonian(self, m):
        """Kinetic energy H(m) = ½ Σ m_i² / I_i."""
        return 0.5 * jnp.sum(m * m * self._inverse_inertia(m), axis=-1)

    def casimir(self, m):
        """C(m) = ½ |m|², conserved by every Poisson map of so(3)*."""
        check_shape(m, "momentum")
        return 0.5 * jnp.sum(m * m, axis=-1)

    def casimirs(self):
        return {"casimir": self.casimir}

    def poisson_matrix(self, m):
        """Π(m) = hat(m), the Lie–Poisson structure of so(3)*."""
        return hat(check_shape(m, "momentum"))

    def vector_field(self, m):
        """ṁ = Π(m) ∇H(m) = m × (I⁻¹ m)."""
        return jnp.cross(m, m * self._inverse_inertia(m))

    def is_physical(self) -> bool:
        """Triangle inequalities I_i + I_j >= I_k (concrete inertia only)."""
        i1, i2, i3 = np.moveaxis(host_values(self.inertia, whole=True), -1, 0)
        return bool(np.all((i1 + i2 >= i3) & (i2 + i3 >= i1) & (i3 + i1 >= i2)))

    def max_rate(self, m0):
        """A bound on every sub-flow's rotation rate along the motion: |m| is a Casimir, so
        |c_k m_k| <= |m0| (max 1/I − min 1/I) for every split."""
        w = 1 / jnp.asarray(self.inertia, dtype=jnp.result_type(m0))
        return jnp.linalg.norm(m0, axis=-1) * (jnp.max(w, axis=-1) - jnp.min(w, axis=-1))

    @property
    def reference_split(self) -> tuple[str, dict]:
        """The split tight references use: two rotations (any fixed shift gives the same flow)."""
        return "casimir", {"shift": 1}

    def equilibria(self):
        """Steady rotations about the principal axes, |m| = 1: the rows of the identity."""
        return jnp.eye(3, dtype=jnp.result_type(self.inertia))

    # ------------------------------------------------------------------ splits
    def splits(self):
        return {"axes": self.axes_split, "casimir": self.casimir_split}

    def axes_split(self) -> tuple:
        """The seed paper's three rotations, H_k = m_k² / (2 I_k)."""
        w = 1 / self.inertia
        return tuple(AxisRotation(k, w[..., k]) for k in range(3))

    def shift_axis(self, shift="auto") -> int:
        """The Casimir shift axis (0-based): ``shift`` itself, or the middle 1/I for "auto"."""
        return shift_axis(self.inertia, shift)

    def casimir_split(self, shift="auto", shift_axis=None) -> tuple:
        """Two rotations: H − C/I_k, k = ``shift`` (0-based) or the middle 1/I ("auto")."""
        if shift_axis is not None:
            raise InputError(f"shift_axis (counted from 1) was renamed shift (counted from 0, like every axis): "
                             f"shift_axis={shift_axis!r} is shift={shift_axis - 1 if shift_axis in (1, 2, 3) else '?'}")
        k = self.shift_axis(shift)
        w = 1 / self.inertia
        return tuple(AxisRotation(i, w[..., i] - w[..., k]) for i in range(3) if i != k)

    def resolve_split(self, name=None, **options):
        name, options = super().resolve_split(name, **options)
        if name == "casimir":
            options["shift"] = self.shift_axis(options.get("shift", "auto"))
        return name, options

    # ------------------------------------------------------------------ exact solution
    def symmetry_axis(self) -> int:
        """The 0-based axis k whose two other moments are equal (concrete inertia)."""
        i = np.asarray(self.inertia)
        for k in (2, 0, 1):
            a, b = (x for x in range(3) if x != k)
            if np.isclose(i[a], i[b], rtol=1e-14, atol=0):
                return k
        raise InputError(f"the body is not symmetric (two equal moments needed), got inertia {i.tolist()}")


def symmetric_solution(body: RigidBody, m0, t, axis: int | None = None):
    """m(t) of a symmetric body from m(0) = m0, for scalar or array ``t``.

    ``axis`` (0-based) is the symmetry axis; found from the inertia when ``None``, which
    needs concrete values (inside ``jit``/``vmap`` over bodies give it, e.g. 2 for I1 = I2).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody(jnp.array([1.0, 1.0, 0.5]))
    >>> m0 = jnp.array([0.4, -0.3, 0.8])
    >>> jaxsplit.symmetric_solution(body, m0, 2.0)          # m3 is constant, (m1, m2) turns
    Array([-0.31155189, -0.39106958,  0.8       ], dtype=float64)
    >>> step = jaxsplit.splitting(body, "strang", split="casimir")   # exact for I1 = I2
    >>> float(jnp.max(jnp.abs(jaxsplit.integrate(step, m0, 0.1, 20).final
    ...                       - jaxsplit.symmetric_solution(body, m0, 2.0)))) < 1e-14
    True
    """
    body = as_body(body)
    if axis is None:
        if not is_concrete(body.inertia):
            raise InputError("symmetric_solution needs axis= when the inertia is traced")
        axis = body.symmetry_axis()
    m0 = as_float_array(m0, "m0")
    t = jnp.asarray(t, dtype=m0.dtype)
    w = 1 / body.inertia
    rotation = AxisRotation(axis, w[..., axis] - w[..., (axis + 1) % 3])
    flat = jax.vmap(lambda s: rotation(m0, s))(t.reshape(-1))
    return flat.reshape(t.shape + m0.shape)


def symmetry_axis(body: RigidBody) -> int:
    return body.symmetry_axis()


class StandardCase(NamedTuple):
    """The asymmetric test case of Hairer–Lubich–Wanner (GNI) with a 30-digit reference.

    Its body (2, 1, 2/3) is not a physical one (1 + 2/3 < 2): the constructors refuse it by
    default, as they refuse any body violating the triangle inequalities. It is kept as the
    literature's case (its reference and the orders measured on it are comparable with the
    papers), so ``body()`` builds it with ``allow_nonphysical=True``: the one place the flag is
    passed for it, where the reason is written. Its moments elsewhere (``attitude``,
    ``heavy_top``, ``reference_solution``, ``sweep``) need the flag at the call.

    >>> import jax.numpy as jnp, jaxsplit
    >>> case = jaxsplit.STANDARD_CASE
    >>> step = jaxsplit.splitting(case.body(), "strang")
    >>> final = jaxsplit.integrate(step, jnp.asarray(case.m0), case.t_end / 1000, 1000).final
    >>> bool(jnp.max(jnp.abs(final - jnp.asarray(case.reference))) < 1e-4)
    True
    """

    inertia: tuple = (2.0, 1.0, 2.0 / 3.0)
    m0: tuple = (float(np.cos(1.1)), 0.0, float(np.sin(1.1)))
    t_end: float = 10.0
    reference: tuple = (0.40706613658804081086, 0.283007426812844076, 0.86844916766156164371)

    def body(self, dtype=None) -> RigidBody:
        """The case's rigid body (moments in ``dtype``, default float), non-physical on purpose."""
        return RigidBody(jnp.asarray(self.inertia, dtype=dtype), allow_nonphysical=True)


STANDARD_CASE = StandardCase()

# The seed paper's symmetric body (I1 = I2 > I3 > 0) used by the default simulation.
PAPER_BODY = (2.0, 2.0, 1.0)
PAPER_M0 = (0.6, 0.0, 0.8)
