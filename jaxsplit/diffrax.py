"""jaxsplit inside diffrax: a solver that composes the exact sub-flows of any system.

Optional extra (``pip install -e ".[diffrax]"``); the core package never imports it.

    >>> import diffrax, jax.numpy as jnp, jaxsplit, jaxsplit.diffrax as jd
    >>> body = jaxsplit.STANDARD_CASE.body()           # (2, 1, 2/3), non-physical on purpose
    >>> sol = diffrax.diffeqsolve(jd.term(body, split="casimir"), jd.Splitting("strang"),
    ...                           0.0, 10.0, 0.05, jnp.array([0.6, 0.0, 0.8]),
    ...                           saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, 10.0, 7)))
    >>> sol.ys.shape
    (7, 3)

The public names:

* ``term(system, split, **options)`` -> ``SplittingTerm``: the exact flows of one split of a
  system of the system layer (its parameters are array leaves: traced, vmapped,
  differentiated) together with the system's vector field ẋ = Π∇H, which diffrax asks for
  only outside the stepping (``solver.func``: initial step-size selection).
* ``Splitting(scheme)``: the diffrax solver. One step from t₀ to t₁ is the scheme's
  composition Ψ_h of the term's flows with h = t₁ − t₀, the same map as
  ``jaxsplit.splitting(system, scheme, split)``. The scheme is static (a new scheme is a new
  compilation); everything else is traced.
* ``RolledSplitting.of(scheme, term, length)``: the same with the scheme's word as traced
  arrays (one compilation for many schemes; ``vmap`` over schemes, ``grad`` in the weights).
* ``PartialStep``: the dense output. The state at t inside a step [t_k, t_k+1] is
  Ψ_δ(x_k) with δ = t − t_k, the *same* composition over the partial interval, so every
  output (``SaveAt(ts=...)``, ``SaveAt(dense=True)``, events) is the image of a Poisson map:
  Casimirs to round-off, the scheme's order. A polynomial (Hermite) interpolant instead
  leaves the symplectic leaf by O(h⁴) (measured in ``tests/test_diffrax.py`` and
  ``benchmarks/diffrax_overhead.py``).

What diffrax features do with it:

* ``ConstantStepSize`` / ``StepTo`` (fixed steps) are the natural mode. ``ConstantStepSize``
  splits [t0, t1] into ⌈(t1 − t0)/dt0⌉ equal steps, so when dt0 does not divide the
  interval the steps are slightly shorter than dt0 (``jaxsplit.integrate`` keeps h and
  stops at n h instead).
* Adaptive controllers (``PIDController``): a composition of exact flows has no embedded
  error estimate, so ``Splitting`` returns none and diffrax refuses the combination when it
  traces ("Cannot use adaptive step sizes with a solver that does not provide error
  estimates"). ``diffrax.HalfSolver(Splitting(scheme))`` supplies one by step doubling
  (3 steps' cost, error order p + 1); every step is still a Poisson map, so Casimirs stay at
  round-off, but a varying step size changes the modified Hamiltonian from step to step and
  the bounded long-time energy error of fixed steps is lost.
* Adjoints: the default ``RecursiveCheckpointAdjoint`` and ``DirectAdjoint`` differentiate
  through the steps (gradients agree with ``jaxsplit.integrate``'s). ``BacksolveAdjoint``
  solves the continuous adjoint ODE with the same solver, whose state is not the system's:
  the forward solve runs, and its gradient is refused (``InputError`` naming the adjoint).
* ``jax.vmap``, ``jax.jit``, progress meters, ``SaveAt(t0=, t1=, ts=, steps=, dense=)`` and
  a negative time direction work as for any diffrax solver; events are located on the dense
  output, so the event state is a partial step too (on the Casimir's level set).
* Refused as ``jaxsplit.integrate`` refuses them: a complex ``y0`` and non-finite concrete
  ``t0``/``t1`` (``InputError`` when the solver starts), a term other than one ``jd.term``
  (an ``ODETerm``, a ``MultiTerm`` of pieces: the message names ``jd.term``); a non-finite
  step (``dt0`` NaN) ends the solve with ``RESULTS.nonfinite``, not ``successful``.
* ``args`` of ``diffeqsolve`` must be ``None``: the exact flows take their parameters from
  the system, so build the term inside the function you vmap or differentiate (refused, not
  ignored).

Uses diffrax's public API only: ``AbstractSolver``, ``AbstractTerm``,
``AbstractLocalInterpolation``, ``RESULTS``. diffrax hands a solver its terms wrapped in a
private time-direction wrapper; the solver finds its ``SplittingTerm`` inside by PyTree
traversal and takes the signed step from the public ``contr`` instead of naming that class.
"""

import abc
from typing import Any, ClassVar

try:
    import diffrax
except ImportError as err:  # pragma: no cover - depends on the environment
    raise ImportError('jaxsplit.diffrax needs diffrax: pip install -e ".[diffrax]"') from err
import equinox as eqx
import jax
import jax.numpy as jnp

from .core._compose import Composition, RolledComposition, compose, roll
from .core._errors import InputError
from .core._flows import AbstractFlow
from .core._schemes import Scheme, schemes
from .core._state import as_state
from .systems._base import AbstractSystem

__all__ = ["PartialStep", "RolledSplitting", "Splitting", "SplittingTerm", "term"]


def _arrays(tree):
    """Python-float leaves as arrays: they are parameters (traced, as in ``integrate``), and
    diffrax stores dense output as arrays."""
    return jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf) if type(leaf) is float else leaf, tree)


class SplittingTerm(diffrax.AbstractTerm):
    """The exact flows of one split of ``system`` as a diffrax term (build it with ``term``).

    ``flows`` is a tuple of flows ``flow(x, t)`` (their array leaves are traced);
    ``system`` supplies the vector field ``vf(t, x, args) = Π(x)∇H(x)``, the same PyTree,
    shapes and dtypes as the state; the control is the signed interval t₁ − t₀ (a scalar).

    >>> import jax.numpy as jnp, jaxsplit, jaxsplit.diffrax as jd
    >>> term = jd.term(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), split="axes")
    >>> len(term.flows), term.vf(0.0, jnp.array([0.6, 0.0, 0.8]), None).shape, term.contr(1.0, 1.5)
    (3, (3,), 0.5)
    """

    flows: tuple
    system: AbstractSystem

    def vf(self, t, y, args):
        return self.system.vector_field(y)

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda v: v * control, vf)


def term(system, split: str | None = None, **options) -> SplittingTerm:
    """The diffrax term of ``system``'s ``split`` (default: its first offered split).

    ``system`` is any ``jaxsplit.AbstractSystem`` (its parameters are traced: build the term
    inside ``vmap``/``grad`` to sweep or differentiate them); ``options`` go to the split,
    e.g. ``shift=1`` for the rigid body's Casimir split (inside ``vmap`` give it explicitly).

    >>> import jaxsplit, jaxsplit.diffrax as jd
    >>> t = jd.term(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), split="casimir", shift=1)
    >>> len(t.flows)
    2
    """
    if not isinstance(system, AbstractSystem):
        raise InputError(f"term needs a system of the system layer (a jaxsplit.AbstractSystem), "
                         f"got {type(system).__name__}")
    return SplittingTerm(_arrays(system.split(split, **options)), system)


def _splitting_term(terms) -> SplittingTerm:
    """The ``SplittingTerm`` inside whatever wrapper diffrax put around it."""
    kinds = (SplittingTerm, diffrax.ODETerm, diffrax.ControlTerm)  # public terms that hold no other term
    is_term = lambda x: isinstance(x, kinds)
    leaves = jax.tree_util.tree_leaves(terms, is_leaf=is_term)
    found = [leaf for leaf in leaves if isinstance(leaf, SplittingTerm)]
    if len(found) != 1:
        others = sorted({type(leaf).__name__ for leaf in leaves if is_term(leaf) and not isinstance(leaf, SplittingTerm)})
        got = f"{len(found)} SplittingTerms" + (f" and {', '.join(others)}" if others else "")
        raise InputError(f"the Splitting solvers take one term, jd.term(system, split), whose flows are every piece "
                         f"of the split (not an ODETerm, not a MultiTerm of pieces); got {got}")
    return found[0]


def _check_start(term, t0, t1, y0):
    """A real state of the term's system (integrate refuses complex ones too) and finite
    concrete times."""
    as_state(y0, "y0")
    try:
        jax.eval_shape(term.system.vector_field, y0)
    except (InputError, TypeError, ValueError) as err:
        raise InputError(f"y0 is not a state of {type(term.system).__name__} ({str(err).splitlines()[0]}); "
                         "diffrax's BacksolveAdjoint hands the solver its adjoint ODE's state, which a splitting "
                         "cannot integrate: use the default adjoint") from None
    for name, t in (("t0", t0), ("t1", t1)):
        if not isinstance(t, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(jnp.asarray(t)))):
            raise InputError(f"{name} must be finite, got {t}")


def _step_result(h):
    """``RESULTS.nonfinite`` for a step that is not finite (a NaN or infinite dt0 reaches the
    solver only as its steps), so diffrax raises (or reports, ``throw=False``) instead of
    returning NaN as a success. A select per step: ``eqx.error_if`` here made a step 3.7x slower."""
    return diffrax.RESULTS.where(jnp.isfinite(h), diffrax.RESULTS.successful, diffrax.RESULTS.nonfinite)


class PartialStep(diffrax.AbstractLocalInterpolation):
    """Dense output of one step: x(t) = Ψ_δ(x₀), δ = t − t₀ signed, a partial step of the scheme.

    ``y0`` is the state at the start of the step, ``h`` the signed step (diffrax's times run
    forward even when the integration runs backward; ``h`` carries the direction), ``step``
    the composition (a flow). ``evaluate(t)`` is exact at both ends: Ψ₀ = id and Ψ_h is the
    step itself. Built by diffrax from the solver's dense information; ``y0`` any PyTree,
    times scalars, all traced.

    >>> import diffrax, jax.numpy as jnp, jaxsplit, jaxsplit.diffrax as jd
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> sol = diffrax.diffeqsolve(jd.term(body, split="casimir", shift=1), jd.Splitting("strang"), 0.0, 1.0, 0.25,
    ...                           jnp.array([0.6, 0.0, 0.8]), saveat=diffrax.SaveAt(dense=True))
    >>> m = sol.evaluate(0.4)                   # a partial step of 0.15 from the grid state at t = 0.25
    >>> round(float(m @ m), 14)
    1.0
    """

    t0: Any
    t1: Any
    y0: Any
    h: Any
    step: AbstractFlow

    def evaluate(self, t0, t1=None, left: bool = True):
        del left
        if t1 is not None:
            return jax.tree_util.tree_map(lambda a, b: a - b, self.evaluate(t1), self.evaluate(t0))
        return self.step(self.y0, (t0 - self.t0) * jnp.sign(self.h))


class _AbstractSplitting(diffrax.AbstractSolver):
    """One step = the composition of the term's flows over h = t₁ − t₀; dense output by
    partial steps; no error estimate. Subclasses say how the composition is built."""

    # any term passes diffrax's structure check, so that ``init`` can say what to pass instead
    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = PartialStep

    @abc.abstractmethod
    def composition(self, flows) -> AbstractFlow:
        """The one-step map of ``flows``."""

    def init(self, terms, t0, t1, y0, args):
        if args is not None:
            raise InputError(f"jaxsplit.diffrax.{type(self).__name__} takes its parameters from the system: pass "
                             "args=None and build the term (jd.term(system, ...)) inside the function you vmap or "
                             "differentiate")
        term = _splitting_term(terms)
        self.composition(term.flows)  # a scheme the split cannot take fails here
        _check_start(term, t0, t1, y0)
        # stateless: diffrax keeps the implicit None as the solver state

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        step = self.composition(_splitting_term(terms).flows)
        h = terms.contr(t0, t1)  # signed: diffrax runs its own times forward
        return step(y0, h), None, {"y0": y0, "h": h, "step": step}, None, _step_result(h)

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class Splitting(_AbstractSplitting):
    """The diffrax solver of a jaxsplit ``scheme`` (a registered name or a ``Scheme``; static).

    Each step is ``jaxsplit.compose(term.flows, scheme)`` over h = t₁ − t₀ (adjacent
    sub-flows of a group piece merged within the step); dense output is a partial step
    (``PartialStep``); no error estimate (see the module docstring for adaptive controllers).
    The order reported to diffrax is the scheme's. A new scheme is a new compilation: to
    run many schemes with one, use ``RolledSplitting``.

    >>> import jaxsplit.diffrax as jd
    >>> jd.Splitting("strang").scheme.order
    2
    """

    scheme: Scheme = eqx.field(static=True, converter=schemes.resolve)

    def order(self, terms) -> int:
        return self.scheme.order

    def composition(self, flows) -> Composition:
        return compose(flows, self.scheme)


class RolledSplitting(_AbstractSplitting):
    """A scheme's word as traced data: one compilation for every scheme of one padded length.

    ``pieces`` (int32, shape (L,)) and ``weights`` (floating, shape (L,)) are the sub-flows in
    the order they act, exactly as in ``jaxsplit.roll``: array leaves, so ``jax.vmap`` runs many
    schemes at once and ``jax.grad`` differentiates with respect to the weights (tuning a
    scheme through ``diffeqsolve``). ``RolledSplitting.of(scheme, term, length)`` builds it
    from the merged word of ``compose(term.flows, scheme)``, padded with identity sub-flows.
    It makes no claim of order (``order`` is ``None``: measure it). Slower per step than
    ``Splitting`` (a ``lax.switch`` per sub-flow, no merging across steps).

    >>> import jaxsplit, jaxsplit.diffrax as jd
    >>> term = jd.term(jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True), split="casimir", shift=1)
    >>> jd.RolledSplitting.of("strang", term, length=4).weights.tolist()
    [0.5, 1.0, 0.5, 0.0]
    """

    pieces: jax.Array
    weights: jax.Array

    @classmethod
    def of(cls, scheme, term: SplittingTerm, length: int | None = None) -> "RolledSplitting":
        """``scheme`` on ``term``'s flows as a rolled word of ``length`` sub-flows (default: its own)."""
        if not isinstance(term, SplittingTerm):
            raise InputError(f"RolledSplitting.of needs a SplittingTerm (from jd.term), got {type(term).__name__}")
        rolled = roll(compose(term.flows, scheme), length)
        return cls(rolled.pieces, rolled.weights)

    def composition(self, flows) -> RolledComposition:
        return RolledComposition(tuple(flows), self.pieces, self.weights)
