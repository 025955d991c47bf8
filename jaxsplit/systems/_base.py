"""The system protocol: a Hamilton–Poisson system and the splits it offers.

A system is an ``equinox.Module`` (its parameters are array fields: traced) that declares

* its state: any PyTree (an array, a tuple of parts, a NamedTuple, a dict);
* ``hamiltonian(x)`` and ``poisson_matrix(x)``: Π as an (n, n) matrix over the n floating
  components of the state in ``ravel`` order (``jaxsplit.core.state.ravel``), so
  ẋ = Π(x) ∇H(x) in those coordinates;
* ``casimirs()``: named functions that every Poisson map of the structure conserves;
  ``invariants()`` adds the energy and any other first integral of this Hamiltonian;
* ``splits()``: named constructors of tuples of exact flows, one per piece of H. A split is
  offered only where it is valid for the system; ``refused_splits`` can say why a familiar
  one is not (the Casimir shift of the free body is not a split of the attitude system).

``split(name, **options)`` checks the name and the options and returns the flows;
``resolve_split`` turns options that need concrete parameters ("auto") into static values,
so batched sweeps can group cases by them.
"""

import abc
import inspect
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core._errors import InputError
from ..core._state import is_floating, ravel


class AbstractSystem(eqx.Module):
    """A Hamilton–Poisson system ẋ = Π(x) ∇H(x) with the splits it offers (see the module docstring).

    The harmonic oscillator x = (q, p), H = ½(q² + p²), split into its two exact shears
    (module-level functions: a flow's function is static, so a new lambda would recompile):

    >>> import jax.numpy as jnp, jaxsplit
    >>> def drift(x, t):
    ...     return x.at[0].add(t * x[1])
    >>> def kick(x, t):
    ...     return x.at[1].add(-t * x[0])
    >>> class Oscillator(jaxsplit.AbstractSystem):
    ...     def hamiltonian(self, x):
    ...         return 0.5 * x @ x
    ...     def poisson_matrix(self, x):
    ...         return jnp.array([[0.0, 1.0], [-1.0, 0.0]])
    ...     def splits(self):
    ...         return {"shears": lambda: (jaxsplit.FunctionFlow(drift), jaxsplit.FunctionFlow(kick))}
    >>> step = jaxsplit.splitting(Oscillator(), "kahan-li-6")
    >>> x = jaxsplit.integrate(step, jnp.array([1.0, 0.0]), 0.1, 10).final
    >>> bool(jnp.allclose(x, jnp.array([jnp.cos(1.0), -jnp.sin(1.0)]), atol=1e-9))
    True
    >>> float(jaxsplit.poisson_defect(step, Oscillator(), x, 0.1)) < 1e-15
    True
    """

    refused_splits: ClassVar[dict[str, str]] = {}

    @abc.abstractmethod
    def hamiltonian(self, x):
        """H(x), a scalar."""

    @abc.abstractmethod
    def poisson_matrix(self, x):
        """Π(x), (n, n) over the n floating components of x in ``ravel`` order."""

    def check_state(self, x):
        """``x`` as a state of this system, checked where concrete (``InputError`` otherwise);
        the flows of its splits call it (``integrate`` checks the initial state). Default:
        any state."""
        return x

    def casimirs(self) -> dict[str, Callable]:
        """Functions conserved by every Poisson map of this structure (name -> x -> scalar)."""
        return {}

    def invariants(self) -> dict[str, Callable]:
        """What the flow conserves: the energy, the Casimirs and any other first integral."""
        return {"energy": self.hamiltonian, **self.casimirs()}

    def splits(self) -> dict[str, Callable[..., tuple]]:
        """Named constructors ``options -> tuple of exact flows`` (one flow per piece of H)."""
        return {}

    @property
    def name(self) -> str:
        return type(self).__name__

    @property
    def default_split(self) -> str:
        offered = self.splits()
        if not offered:
            raise InputError(f"{self.name} offers no split into exactly solvable pieces (use a Runge–Kutta "
                             "method, or write the flows and compose them)")
        return next(iter(offered))

    @property
    def reference_split(self) -> tuple[str, dict]:
        """(split, options) for tight reference integrations (default: the first split)."""
        return self.default_split, {}

    def _lookup(self, name):
        offered = self.splits()
        name = self.default_split if name is None else name
        if name not in offered:
            why = self.refused_splits.get(name)
            reason = f": {why}" if why else ""
            raise InputError(f"split {name!r} is not offered by {self.name}{reason}; "
                             f"offered: {', '.join(offered) or 'none'}")
        return name, offered[name]

    def split(self, name: str | None = None, **options) -> tuple:
        """The exact flows of split ``name`` (default: the first offered) with ``options``."""
        name, build = self._lookup(name)
        params = inspect.signature(build).parameters
        unknown = sorted(set(options) - set(params))
        if unknown:
            allowed = ", ".join(params) or "no options"
            raise InputError(f"split {name!r} of {self.name} takes {allowed}; got {', '.join(unknown)}")
        return tuple(build(**options))

    def resolve_split(self, name: str | None = None, **options) -> tuple[str, dict]:
        """(name, options) with every option that depends on concrete parameters made explicit."""
        name, _ = self._lookup(name)
        return name, dict(options)

    def vector_field(self, x):
        """ẋ = Π(x) ∇H(x) (integer leaves are constants: their rate is 0)."""
        flat, unravel = ravel(x)
        grad = jax.grad(lambda v: self.hamiltonian(unravel(v)))(flat)
        rate = unravel(self.poisson_matrix(x) @ grad)
        return jax.tree_util.tree_map(lambda r: r if is_floating(r) else jnp.zeros_like(r), rate)

    def bracket(self, f, g, x):
        """{f, g}(x) = ∇f(x)ᵀ Π(x) ∇g(x)."""
        flat, unravel = ravel(x)
        df = jax.grad(lambda v: f(unravel(v)))(flat)
        dg = jax.grad(lambda v: g(unravel(v)))(flat)
        return df @ self.poisson_matrix(x) @ dg

    def monitored(self) -> tuple:
        """(name, function) pairs of ``invariants()`` (for ``monitor_invariants``)."""
        return tuple(self.invariants().items())
