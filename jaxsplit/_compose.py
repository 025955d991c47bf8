"""One generic composer: (exact flows, scheme) -> a pure ``step(state, h)``.

A scheme is first reduced to a *word*: the sequence of (piece, weight) sub-flows, the
first entry acting first. Because every piece is an exact flow, hence a one-parameter
group (φ_a ∘ φ_b = φ_{a+b}), adjacent sub-flows of the same piece merge into one. When a
word begins and ends with the same piece (every symmetric scheme), consecutive steps
merge across the step boundary as well (first-same-as-last); ``Composition.advance``
does that inside its ``lax.scan``.

A flow is any pure function ``flow(state, t, params) -> state`` that is the exact
time-t flow of one piece; the state may be any PyTree.
"""

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import InputError
from ._schemes import Scheme, schemes

Word = tuple[tuple[int, float], ...]


def word(scheme: Scheme, n_pieces: int) -> Word:
    """The scheme as a sequence of (piece index, weight), unmerged, zero weights dropped."""
    if not scheme.pieces_allowed(n_pieces):
        raise InputError(
            f"scheme {scheme.name!r} ({scheme.form}) needs exactly 2 pieces, "
            f"the splitting has {n_pieces}; use split='casimir' or a non-partitioned scheme"
        )
    c = scheme.coefficients

    def lie(w):  # Φ_{wh}: the first piece acts first
        return [(p, w) for p in range(n_pieces)]

    def adjoint(w):  # Φ*_{wh}: the last piece acts first
        return [(p, w) for p in reversed(range(n_pieces))]

    entries = []
    if scheme.form == "partitioned":
        entries = [(k % 2, w) for k, w in enumerate(c)]
    elif scheme.form == "lie-adjoint":  # Φ_{α2 h} ∘ Φ*_{α1 h} ∘ …: the adjoint acts first
        for a_adjoint, a_lie in zip(c[0::2], c[1::2]):
            entries += adjoint(a_adjoint) + lie(a_lie)
    else:  # Strang S_h = Φ*_{h/2} ∘ Φ_{h/2}: the paper's φ²_t, first piece at both ends
        for g in c:
            entries += lie(g / 2) + adjoint(g / 2)
    return tuple((p, w) for p, w in entries if w != 0.0)


def merge(w: Word) -> Word:
    """Merge adjacent sub-flows of the same piece (exact for one-parameter groups)."""
    out: list[list] = []
    for piece, weight in w:
        if out and out[-1][0] == piece:
            out[-1][1] += weight
            if out[-1][1] == 0.0:
                out.pop()
        else:
            out.append([piece, weight])
    return tuple((p, w) for p, w in out)


def _apply(flows, params, w: Word, state, h):
    for piece, weight in w:
        # The barrier keeps XLA from fusing a whole step into one kernel that recomputes
        # earlier sub-flows: without it the cost grows geometrically with the word length
        # (Kahan-Li 6 on the axes split: minutes per step), with it ~20 ns per rotation.
        state = jax.lax.optimization_barrier(flows[piece](state, weight * h, params))
    return state


@jax.tree_util.register_pytree_node_class
@dataclasses.dataclass(frozen=True)
class Composition:
    """A composed one-step map; call it as ``step(state, h)``.

    ``params`` (e.g. the body) is the only traced part, so the same composition with new
    parameters or a new ``h`` reuses compiled code; ``flows`` and ``word`` are static.
    """

    flows: tuple[Callable, ...]
    word: Word
    params: Any = None
    scheme: Scheme | None = None
    fsal: bool = False

    def __call__(self, state, h):
        return _apply(self.flows, self.params, self.word, state, _like_state(h, state))

    def advance(self, state, h, n: int):
        """``n`` steps, merging the last sub-flow of each step with the first of the next."""
        h = _like_state(h, state)
        if n == 0:
            return state
        if not self.fsal or n == 1:
            return jax.lax.scan(lambda x, _: (self(x, h), None), state, length=n)[0]
        (piece, first), middle, (_, last) = self.word[0], self.word[1:-1], self.word[-1]
        joint = middle + ((piece, last + first),)

        def body(x, _):
            return _apply(self.flows, self.params, joint, x, h), None

        state = _apply(self.flows, self.params, ((piece, first),), state, h)
        state = jax.lax.scan(body, state, length=n - 1)[0]
        return _apply(self.flows, self.params, middle + ((piece, last),), state, h)

    @property
    def flows_per_step(self) -> int:
        """Sub-flows evaluated per step in a long run (after all merging)."""
        return len(self.word) - (1 if self.fsal else 0)

    def tree_flatten(self):
        return (self.params,), (self.flows, self.word, self.scheme, self.fsal)

    @classmethod
    def tree_unflatten(cls, aux, children):
        flows, w, scheme, fsal = aux
        return cls(flows, w, children[0], scheme, fsal)


@jax.tree_util.register_pytree_node_class
class RolledComposition:
    """The same map as a ``Composition``, its word run by ``lax.scan`` + ``lax.switch`` with
    the pieces and weights as traced arrays.

    Compile time no longer grows with the word, and every scheme over the same flows (padded
    to one length with identity sub-flows) shares ONE compilation: the right form for checks
    over a whole registry, sweeps and optimisation loops. The unrolled ``Composition`` runs
    faster (no switch, merging across steps); prefer it for long integrations.
    """

    def __init__(self, flows, pieces, weights, params):
        self.flows, self.pieces, self.weights, self.params = tuple(flows), pieces, weights, params

    def __call__(self, state, h):
        h = _like_state(h, state)
        branches = [functools.partial(_call_flow, f, self.params) for f in self.flows]

        def sub_flow(x, piece_weight):
            piece, weight = piece_weight
            return jax.lax.switch(piece, branches, x, weight.astype(h.dtype) * h), None

        return jax.lax.scan(sub_flow, state, (self.pieces, self.weights))[0]

    def tree_flatten(self):
        return (self.pieces, self.weights, self.params), self.flows

    @classmethod
    def tree_unflatten(cls, flows, children):
        return cls(flows, *children)


def _call_flow(flow, params, state, t):
    return flow(state, t, params)


def roll(composition: Composition, length: int | None = None) -> RolledComposition:
    """``composition`` as a ``RolledComposition``, padded to ``length`` sub-flows."""
    w = tuple(composition.word)
    length = len(w) if length is None else int(length)
    if length < len(w):
        raise InputError(f"length must be at least the word length {len(w)}, got {length}")
    padded = w + ((0, 0.0),) * (length - len(w))
    pieces = jnp.asarray(np.array([p for p, _ in padded], dtype=np.int32))
    weights = jnp.asarray(np.array([c for _, c in padded]))
    return RolledComposition(composition.flows, pieces, weights, composition.params)


def _like_state(h, state):
    """The step size in the state's floating dtype (never the other way round)."""
    dtype = jnp.result_type(*jax.tree_util.tree_leaves(state))
    return jnp.asarray(h, dtype=dtype)


def compose(flows: Sequence[Callable], scheme: "Scheme | str", params=None, *, merge_flows: bool = True
            ) -> Composition:
    """Compose exact ``flows`` (``flow(state, t, params)``) by ``scheme`` into one step.

    ``merge_flows=False`` keeps every sub-flow of the scheme as written (for checking the
    merging, which must agree to round-off).
    """
    scheme = schemes.resolve(scheme)
    flows = tuple(flows)
    w = word(scheme, len(flows))
    if merge_flows:
        w = merge(w)
    fsal = merge_flows and len(w) >= 2 and w[0][0] == w[-1][0]
    return Composition(flows, w, params, scheme, fsal)
