"""The flow abstraction: the time-t map of one piece of a splitting, as a PyTree module.

A flow is an ``equinox.Module`` called as ``flow(state, t)``. Its array fields are its
parameters: traced wherever they sit (a new value reuses compiled code, ``vmap`` sweeps it,
``grad`` differentiates it); structural choices (an axis index, a state layout) are static
fields. ``is_group`` says whether the flow is an exact one-parameter group,
φ_s ∘ φ_t = φ_{s+t}: only such flows may be merged by the composer. A ``Composition`` is a
flow too (not a group), so compositions nest.
"""

import abc
import weakref
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._errors import InputError
from ._state import fits_batch


def _is_parameter(leaf) -> bool:
    return eqx.is_array(leaf) or type(leaf) is float


def split_parameters(module):
    """(parameters: the array and float leaves, static: (treedef, the other leaves)); the
    parameter list has one entry per leaf, ``None`` where the leaf is not a parameter."""
    leaves, treedef = jax.tree_util.tree_flatten(module)
    parameters = [leaf if _is_parameter(leaf) else None for leaf in leaves]
    static = tuple(None if _is_parameter(leaf) else leaf for leaf in leaves)
    return parameters, (treedef, static)


def join_parameters(parameters, static):
    treedef, others = static
    return jax.tree_util.tree_unflatten(treedef, [p if s is None else s for p, s in zip(parameters, others)])


class AbstractFlow(eqx.Module):
    """``flow(state, t) -> state``: the time-``t`` map of one piece (subclass it for your flows).

    ``state`` is any PyTree, ``t`` a real scalar (signed; the composer passes weight × h in
    the state's dtype); the result has the state's structure, shapes and dtypes. Array fields
    are parameters (traced by ``jit``, batched by ``vmap``, differentiated by ``grad``); mark
    structure (an axis, a layout) ``eqx.field(static=True)``. Override ``is_group`` to return
    ``False`` for a map that is not an exact one-parameter group (it is then never merged).

    >>> import equinox as eqx, jax, jax.numpy as jnp, jaxsplit
    >>> class Shear(jaxsplit.AbstractFlow):     # exact flow of H = p²/2 on (q, p)
    ...     def __call__(self, x, t):
    ...         return x[0] + t * x[1], x[1]
    >>> Shear()((jnp.array(1.0), jnp.array(2.0)), 0.5)[0].item()
    2.0
    """

    @abc.abstractmethod
    def __call__(self, state, t):
        raise NotImplementedError

    # ``jax.jit(step)`` hashes and compares the function: arrays count by identity (a module
    # holding arrays is otherwise unhashable, and comparing array values inside a trace fails).
    # A partitioned module (``eqx.filter_jit``'s static half, arrays replaced by None) hashes
    # and compares by structure, as equinox does.
    def _identity_key(self):
        leaves, treedef = jax.tree_util.tree_flatten(self)
        return treedef, tuple(("array", id(leaf)) if eqx.is_array(leaf) else leaf for leaf in leaves)

    def __hash__(self):
        try:
            return super().__hash__()  # by fields: a module without arrays (a static half)
        except TypeError:
            return hash(self._identity_key())

    def __eq__(self, other):
        return self is other or (type(self) is type(other) and self._identity_key() == other._identity_key())

    @property
    def is_group(self) -> bool:
        """An exact one-parameter group (adjacent sub-flows may merge). Default: yes."""
        return True

    @property
    def uses_selects(self) -> bool:
        """Whether this flow's kernel uses the select form inside jaxsplit's loops (constant tests
        that must stay inside the loop's kernels: ``core._loops``). Default: no."""
        return False

    def turn_rate(self, x):
        """A bound ω (a scalar array) with |angle| <= ω·|t| for every rotation this flow evaluates
        at every state a run from ``x`` reaches, where every flow of the run declares one (each
        then keeps what bounds it: a rotation of m keeps |m|); None (default): no bound. It lets
        a run pick a shorter rotation kernel inside the compiled program (``_angles``)."""
        return None

    @property
    def is_reversible(self) -> bool:
        """φ_{−t} = φ_t⁻¹ exactly (a group flow, a time-symmetric composition of such flows):
        what the reversible adjoint needs to rebuild states by stepping back."""
        return self.is_group

    def check_state(self, x):
        """Refuse (``InputError``) a concrete state this flow would integrate to garbage that
        still looks fine (an attitude that is no rotation); traced values pass. ``integrate``
        calls it on the initial state. Default: the checks of the flows this one is made of
        (a composition's pieces), each kind once."""
        for check, flow in _state_checks(self):
            check(flow, x)
        return x

    def step_back(self, x_after, t, ct_after):
        """One call of the reversible adjoint's backward pass: the state before this flow,
        x = φ_{−t}(x_after), and the cotangent ``ct_after`` pulled back through φ_t at x:
        ``(x, ct_x, ct_parameters, ct_t)`` with ``ct_parameters`` one entry per leaf of the
        flow (``split_parameters`` order, ``None`` where a leaf is not a parameter). An entry
        may keep the axes a leaf was broadcast along (a batch of states), and ``ct_t`` may be
        one value per state: the caller sums them (``sum_to_shape``) once, after the last step,
        instead of reducing over the batch at every sub-flow.

        Default: φ_{−t} and ``jax.vjp`` of one call. A flow can fuse both (a rotation shares
        its cos and sin between the inverse and the pullback; its angle is unchanged)."""
        x = self(x_after, -t)
        parameters, static = split_parameters(self)
        _, pullback = jax.vjp(lambda p, y, s: join_parameters(p, static)(y, s), parameters, x, t)
        ct_parameters, ct_x, ct_t = pullback(ct_after)
        return x, ct_x, ct_parameters, ct_t


def sub_flows(module):
    """The flows ``module`` is made of: its fields that are flows or tuples of flows."""
    for value in vars(module).values():
        for item in value if isinstance(value, tuple | list) else (value,):
            if isinstance(item, AbstractFlow):
                yield item


def _leaf_flows(flow):
    subs = tuple(sub_flows(flow))
    if not subs:
        yield flow
    for sub in subs:
        yield from _leaf_flows(sub)


def _state_checks(step) -> tuple:
    """((unbound check_state, flow), ...) of the flows ``step`` is made of that declare one, one
    per kind (a type and the parts it declares accept the same states: a composition's three
    rotations of (m, Q) check Q once). Remembered per step: walking an equinox module's fields
    and looking up its methods (a bound method of a module is a module built per lookup) cost
    more than a small run."""
    entry = _CHECKS.get(id(step))
    if entry is not None and entry[0]() is step:
        return entry[1]
    kinds = {}
    for flow in _leaf_flows(step):
        check = type(flow).check_state
        if flow is not step and check is not AbstractFlow.check_state:
            kinds.setdefault((type(flow), getattr(flow, "parts", None)), (check, flow))
    checks = tuple(kinds.values())
    ident = id(step)
    _CHECKS[ident] = (weakref.ref(step, lambda _: _CHECKS.pop(ident, None)), checks)
    return checks


_CHECKS: dict = {}  # id(step) -> (weak reference, its checks): forgotten with the step


def check_state(step, x):
    """``x`` refused where ``step`` (a flow) declares it cannot integrate it (``check_state``);
    a plain function declares nothing. Called through the class: cheap for a remembered step.
    A state spread over several processes (a global array) is checked in each process on the
    part it holds (the checks read values through ``_state.host_values``)."""
    if isinstance(step, AbstractFlow):
        type(step).check_state(step, x)
    return x


def sum_to_shape(a, shape):
    """``a`` summed over the axes it was broadcast along from ``shape`` (a parameter's cotangent)."""
    a = jnp.sum(a, axis=tuple(range(a.ndim - len(shape))))
    return jnp.sum(a, axis=tuple(q for q, size in enumerate(shape) if size == 1), keepdims=True).reshape(shape)


def _is_none(leaf) -> bool:
    return leaf is None


def _add_scaled(x, t, v):
    """x + t·v on every leaf of ``v`` (a PyTree like ``x``, ``None`` where x is left as it is)."""
    return jax.tree_util.tree_map(lambda v_leaf, x_leaf: x_leaf if v_leaf is None else x_leaf + t * v_leaf,
                                  v, x, is_leaf=_is_none)


class AbstractKick(AbstractFlow):
    """A kick x ← x + t·v(x) whose velocity ``v`` is constant along it, v(x + s·v(x)) = v(x)
    (``v`` reads only parts the kick leaves fixed, e.g. m ← m + t Γ × ∇V(Γ) with Γ fixed): the
    exact flow, a one-parameter group. Subclasses give ``velocity(state)``: a PyTree like the
    state, ``None`` where a part does not move.

    Its ``step_back`` is fused: one ``jax.vjp`` of ``v`` alone at x_after (v and its Jacobian
    there are those at x) gives x = x_after − t·v and pulls the cotangent back,
    ct_x = ct + (∂v/∂x)ᵀ(t·ct), ct_t = ⟨ct, v⟩, ct_parameters = (∂v/∂p)ᵀ(t·ct) (the generic
    pullback differentiates the whole call after evaluating it once more).

    >>> import jax.numpy as jnp, jaxsplit
    >>> class Push(jaxsplit.AbstractKick):      # p ← p − t k q, q fixed: the kick of k q²/2
    ...     k: jnp.ndarray
    ...     def velocity(self, x):
    ...         return None, -self.k * x[0]
    >>> Push(jnp.array(2.0))((jnp.array(1.0), jnp.array(0.0)), 0.5)[1].item()
    -1.0
    """

    @abc.abstractmethod
    def velocity(self, state):
        raise NotImplementedError

    def __call__(self, state, t):
        return _add_scaled(state, t, self.velocity(state))

    def step_back(self, x_after, t, ct_after):
        # v and ∂v/∂x read only the parts the kick leaves fixed, so at x_after they are those at x:
        # one evaluation serves the inverse step and the pullback (bit-identical; a heavy top's
        # gradient 6 % faster than a second evaluation at x)
        parameters, static = split_parameters(self)
        v, pullback = jax.vjp(lambda p, y: join_parameters(p, static).velocity(y), parameters, x_after)
        x = _add_scaled(x_after, -t, v)
        ct_moved = jax.tree_util.tree_map(lambda v_leaf, ct: None if v_leaf is None else ct, v, ct_after,
                                          is_leaf=_is_none)  # the cotangent of the parts that move
        ct_parameters, ct_x = pullback(jax.tree_util.tree_map(lambda ct: t * ct, ct_moved))
        ct_x = jax.tree_util.tree_map(jnp.add, ct_after, ct_x)
        ct_t = sum(jnp.sum(a * b) for a, b in zip(jax.tree_util.tree_leaves(ct_moved), jax.tree_util.tree_leaves(v)))
        return x, ct_x, ct_parameters, ct_t


class FunctionFlow(AbstractFlow):
    """A plain function ``fn(state, t)`` (or ``fn(state, t, params)`` with ``params`` and
    ``with_params=True``) as a flow.

    ``fn`` is static (hashed: a new function compiles anew); ``params`` is a PyTree of arrays
    (traced); ``group=False`` declares a map that is not an exact one-parameter group (then it
    is never merged). State and ``t`` as for ``AbstractFlow``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> kick = jaxsplit.FunctionFlow(lambda x, t, k: (x[0], x[1] - t * k * x[0]), jnp.array(2.0),
    ...                              with_params=True)
    >>> kick((jnp.array(1.0), jnp.array(0.0)), 0.5)[1].item()
    -1.0
    """

    fn: Callable = eqx.field(static=True)
    params: Any = None
    group: bool = eqx.field(static=True, default=True)
    with_params: bool = eqx.field(static=True, default=False)

    def __call__(self, state, t):
        return self.fn(state, t, self.params) if self.with_params else self.fn(state, t)

    @property
    def is_group(self) -> bool:
        return self.group


class Substeps(AbstractFlow):
    """``flow`` applied ``n`` times with step t/n: sub-stepping a stiff or inexact piece.

    ``n`` is static (an int >= 1); the inner flow's parameters stay traced. The result is not
    a group flow (never merged). State and ``t`` as for ``AbstractFlow``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> euler = jaxsplit.FunctionFlow(lambda x, t: x + t * x, group=False)   # not exact
    >>> round(jaxsplit.Substeps(euler, 100)(jnp.array(1.0), 1.0).item(), 4)   # (1 + 1/100)^100
    2.7048
    """

    flow: AbstractFlow
    n: int = eqx.field(static=True)

    def __check_init__(self):
        if isinstance(self.n, bool) or not isinstance(self.n, int) or self.n < 1:
            raise InputError(f"Substeps needs an integer n >= 1, got {self.n!r}")

    def __call__(self, state, t):
        return jax.lax.fori_loop(0, self.n, lambda _, x: self.flow(x, t / self.n), state)

    @property
    def is_group(self) -> bool:
        return False

    @property
    def is_reversible(self) -> bool:
        return self.flow.is_reversible


class Renormalized(AbstractFlow):
    """``step`` followed by a projection: every part of the state named in ``norms`` is scaled
    back to its norm (over the last axis), x ← x·r/|x|.

    For long low-precision runs: a splitting conserves |m| exactly, but in float32 round-off
    drifts it (Kahan–Li 6, 2·10⁴ steps: above 1e-5 relative, ``tests/test_cli_systems.py``);
    projecting back onto the sphere keeps it at the float32 round-off (within 4 ulp there). It
    restores the norms, not accuracy: the distance to the exact solution is not reduced. It is
    a projection, not part of the scheme: the map is
    no longer exactly a composition of exact flows, so say so where it is used. ``norms`` is
    a PyTree matching the state with a norm (array) where to project and ``None`` elsewhere,
    e.g. ``jnp.linalg.norm(m0)`` for the free body, ``(None, 1.0)`` for a heavy top's Γ.
    The norms are traced (array leaves); the state keeps its structure and dtypes.

    >>> import jax.numpy as jnp, jaxsplit
    >>> m0 = jnp.array([0.6, 0.0, 0.8], dtype=jnp.float32)
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)     # 1 + 0.5 < 2: on purpose
    >>> step = jaxsplit.splitting(body, "strang", "casimir", shift=1)
    >>> m = jaxsplit.integrate(jaxsplit.Renormalized(step, jnp.linalg.norm(m0)), m0, 0.1, 100).final
    >>> m.dtype, bool(abs(float(jnp.linalg.norm(m)) - 1.0) < 1e-6)
    (dtype('float32'), True)
    """

    step: Any
    norms: Any

    def __call__(self, state, t):
        state = self.step(state, t)
        return jax.tree_util.tree_map(_rescale, self.norms, state, is_leaf=lambda n: n is None)

    @property
    def is_group(self) -> bool:
        return False

    @property
    def scheme(self):
        return getattr(self.step, "scheme", None)


def _rescale(norm, x):
    if norm is None:
        return x
    r = jnp.asarray(norm, dtype=x.dtype)
    batch = jnp.shape(x)[:-1]
    if not fits_batch(jnp.shape(r), batch):  # a (B, 1) norm would broadcast a (B, 3) batch to (B, B, 3)
        raise InputError(f"Renormalized: a norm of shape {jnp.shape(r)} does not fit states of batch shape {batch}; "
                         f"give one norm per state (shape {batch}, e.g. jnp.linalg.norm(m0, axis=-1)) or a scalar")
    return x * (r / jnp.linalg.norm(x, axis=-1))[..., None]


def as_flow(flow, params=None) -> AbstractFlow:
    """A flow module from a module, or from a function ``fn(state, t[, params])``."""
    if isinstance(flow, AbstractFlow):
        if params is not None:
            raise InputError("params= applies to plain-function flows; a flow module carries its own parameters")
        return flow
    if not callable(flow):
        raise InputError(f"a flow must be callable as flow(state, t), got {flow!r}")
    return FunctionFlow(flow, params, with_params=params is not None)
