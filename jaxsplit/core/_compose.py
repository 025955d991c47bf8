"""One generic composer: (flows, scheme) -> a ``Composition``, itself a flow.

A scheme is first reduced to a *word*: the sequence of (piece, weight) sub-flows, the
first entry acting first. Adjacent sub-flows of the same piece merge into one when that
piece is an exact one-parameter group (φ_a ∘ φ_b = φ_{a+b}). When a word begins and ends
with the same group piece (every symmetric scheme), consecutive steps merge across the step
boundary as well (first-same-as-last); ``Composition.advance`` does that inside its
``lax.scan``. ``roll`` gives the same map with the word as array data, so that every scheme
of a given word length shares one compilation.
"""

import contextlib
import functools
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._angles import by_angle_bound
from ._errors import InputError
from ._flows import AbstractFlow, as_flow, split_parameters, sum_to_shape
from ._loops import plain_loops, repeated, threaded
from ._schemes import Scheme, schemes
from ._state import float_dtype

Word = tuple[tuple[int, float], ...]


class _Whole(tuple):
    """A word stored whole: a tuple that JAX's tree functions see as one leaf. Equinox checks
    every leaf of a module's static fields whenever one is built or flattened (every jit
    call): Blanes–Casas–Murua 8's word and processor are ~250 (piece, weight) leaves, 342 µs
    a build, 56 µs kept whole. Equal to, hashed and printed as the plain tuple."""

    __slots__ = ()


def _whole(w):
    return w if isinstance(w, _Whole) else _Whole(w)


def _whole_parts(processing):
    return None if processing is None else tuple(_whole(w) for w in processing)


def word(scheme: Scheme, n_pieces: int) -> Word:
    """The scheme as a sequence of (piece index, weight), unmerged, zero weights dropped."""
    if not scheme.pieces_allowed(n_pieces):
        raise InputError(
            f"scheme {scheme.name!r} ({scheme.form}) needs exactly 2 pieces, "
            f"the splitting has {n_pieces}; use a two-piece split (e.g. split='casimir') or a "
            "non-partitioned scheme"
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


def processor_words(scheme: Scheme, n_pieces: int) -> tuple[Word, Word]:
    """(P, P⁻¹) of a processed scheme as words, () for others: P the Strang steps of the
    processor weights, P⁻¹ the same sub-flows reversed with negated weights (exact for group
    flows, φ_{−t} = φ_t⁻¹)."""
    if not scheme.processed:
        return (), ()
    pre = word(schemes["strang"], n_pieces)  # one Strang step of unit size
    pre = tuple((p, w * g) for g in scheme.processor for p, w in pre if w * g != 0.0)
    return pre, tuple((p, -w) for p, w in reversed(pre))


def merge(w: Word, mergeable=None) -> Word:
    """Merge adjacent sub-flows of the same piece; ``mergeable[p]`` False keeps piece p's
    sub-flows apart (only exact one-parameter groups merge)."""
    out: list[list] = []
    for piece, weight in w:
        if out and out[-1][0] == piece and (mergeable is None or mergeable[piece]):
            out[-1][1] += weight
            if out[-1][1] == 0.0:
                out.pop()
        else:
            out.append([piece, weight])
    return tuple((p, w) for p, w in out)


def _period(pieces: tuple[int, ...]) -> int:
    """The shortest p with pieces[k] == pieces[k − p] for every k >= p (the sequence repeats a
    pattern of p pieces; a tail shorter than p is a prefix of it)."""
    return next(p for p in range(1, len(pieces) + 1) if pieces[p:] == pieces[:len(pieces) - p])


# Per-step words longer than this run their repeating pattern as a loop (``run_word``): unrolled,
# every sub-flow is a kernel of its own for XLA and LLVM to compile, and the compile time grew
# with the word (a heavy top's Kahan–Li 6: 55 sub-flows, 21 s); rolled, one pattern compiles
# whatever the length (``benchmarks/results/transformed.md``: compile and run times, rolled
# and unrolled, per scheme).
UNROLLED_UP_TO = 8


def run_word(w: Word, carry, one, invariants, guarded: bool = False):
    """``carry = one(piece, weight, carry, invariants)`` for each (piece, weight) of ``w`` in order;
    ``invariants`` is (flows, h).

    A word longer than ``UNROLLED_UP_TO`` that repeats a pattern of pieces (every scheme's does:
    a Strang or Lie step's pieces in a fixed order, only the weights differ) runs as a loop over
    the repetitions, the weights a (repetitions, period) array indexed by the loop count; the
    rest is unrolled with the weights as Python floats. ``guarded`` (flows that use the select
    form, ``uses_selects``): the loop is ``_loops.threaded``'s (not one kernel of its own: it
    sits inside the stepping loop's), so every value it uses goes through the barrier with its
    state and the select form's tests stay in its kernels (a plain scan ran Kahan–Li 8 on 256
    free bodies 1.25× slower); else a plain ``lax.scan`` over the weights (the threaded loop
    ran 256 heavy tops 2.5× slower: its barrier keeps XLA from simplifying the flows' parameters).
    Each sub-flow ends in an optimization barrier: without it XLA fuses a whole word into one
    kernel that recomputes earlier sub-flows, and the cost grows geometrically with the word
    length (Kahan-Li 6 on the axes split: minutes per step), with it ~20 ns per rotation.
    """
    pieces = tuple(p for p, _ in w)
    period = _period(pieces) if pieces else 1
    reps = len(w) // period if len(w) > UNROLLED_UP_TO else 0
    if reps >= 2:
        # the weights in the step size's dtype (invariants = (flows, h), h in the state's): a
        # float32 state must not meet float64 weights (the flows' parameters may be float64)
        weights = jnp.asarray(np.array([c for _, c in w[:reps * period]]).reshape(reps, period),
                              jnp.result_type(invariants[1]))

        def repetition(carry_k, inv_weights):
            c, k = carry_k
            inv, ws = inv_weights
            row = ws[k]
            for q in range(period):
                c = jax.lax.optimization_barrier(one(pieces[q], row[q], c, inv))
            return c, k + 1

        if guarded:
            carry, _ = threaded(repetition, (carry, jnp.zeros((), jnp.int32)), (invariants, weights), reps,
                                one_call=False)
        else:
            def plain(c, row):
                for q in range(period):
                    c = jax.lax.optimization_barrier(one(pieces[q], row[q], c, invariants))
                return c, None

            carry = jax.lax.scan(plain, carry, weights)[0]
        w = w[reps * period:]
    for piece, weight in w:
        carry = jax.lax.optimization_barrier(one(piece, weight, carry, invariants))
    return carry


def _sub_flow(piece, weight, state, flows_h):
    flows, h = flows_h
    return flows[piece](state, weight * h)


def _guarded(flows) -> bool:
    return any(f.uses_selects for f in flows)


def _apply(flows, w: Word, state, h):
    return run_word(w, state, _sub_flow, (flows, h), _guarded(flows))


# Sub-flow sequences run once per call (a processor's P and P⁻¹) longer than this that repeat no
# pattern run as data (``_apply_rolled``): unrolled, each sub-flow is a kernel of its own to compile.
ROLLED_ABOVE = 8


def _as_arrays(w: Word, dtype=None):
    """A word as data: (pieces int32 (L,), weights (L,))."""
    return (jnp.asarray(np.array([p for p, _ in w], dtype=np.int32)),
            jnp.asarray(np.array([c for _, c in w], dtype=np.float64), dtype=dtype))


def _apply_rolled(flows, pieces, weights, state, h):
    """``_apply`` with the word as data: a ``lax.scan`` over its (piece, weight) pairs, each a
    ``lax.switch`` over the flows; one compiled sub-flow per piece whatever the length."""
    branches = [lambda x, t, f=f: f(x, t) for f in flows]

    def sub_flow(x, piece_weight):
        piece, weight = piece_weight
        return jax.lax.switch(piece, branches, x, weight.astype(h.dtype) * h), None

    return jax.lax.scan(sub_flow, state, (pieces, weights))[0]


def _irregular(w: Word) -> bool:
    """A long sequence that ``run_word`` would leave unrolled (no repeating pattern)."""
    return len(w) > ROLLED_ABOVE and len(w) // _period(tuple(p for p, _ in w)) < 2


def _apply_once(flows, w: Word, state, h):
    """A sequence run once per call: as ``_apply``, or as data where long and irregular."""
    if _irregular(w):
        return _apply_rolled(flows, *_as_arrays(w, h.dtype), state, h)
    return _apply(flows, w, state, h)


def _like_state(h, state):
    """The step size in the state's floating dtype (never the other way round)."""
    return jnp.asarray(h, dtype=float_dtype(state))


def _joint_layout(state, cotangent):
    """(pack, unpack) for the reversible adjoint's carry: the state and its cotangent as ONE
    array (their leaves stacked) when every leaf has one shape and dtype, else the pair as it is.

    Why: XLA writes each output array of a sub-flow with a kernel of its own; as one array,
    a rotation turns the state and the cotangent in one kernel instead of one per leaf
    (10³ heavy tops: gradient / forward 2.5× → 2.0×, bit-identical; 10³ free bodies 2.4× → 2.1×;
    one state: the same time, other fusion, so round-off differs)."""
    leaves, treedef = jax.tree_util.tree_flatten(state)
    if len({(jnp.shape(leaf), jnp.result_type(leaf)) for leaf in leaves + jax.tree_util.tree_leaves(cotangent)}) != 1:
        return (lambda x, ct: (x, ct)), (lambda joint: joint)
    size = len(leaves)

    def pack(x, ct):
        return jnp.stack(jax.tree_util.tree_leaves(x) + jax.tree_util.tree_leaves(ct))

    def unpack(joint):
        return tuple(jax.tree_util.tree_unflatten(treedef, list(joint[k * size:(k + 1) * size])) for k in (0, 1))

    return pack, unpack


@functools.cache
def _sequences(parts, fsal: bool):
    pre, kernel, post = parts
    if not fsal:
        return pre, kernel, post
    (piece, first), middle, (_, last) = kernel[0], kernel[1:-1], kernel[-1]
    return merge(pre + ((piece, first),)), middle + ((piece, last + first),), merge(((piece, -first),) + post)


@functools.cache
def _entries(word, parts, fsal: bool) -> Word:
    return word + sum(_sequences(parts, fsal), ())


@functools.cache
def _reach(entries: Word, n_flows: int) -> tuple[float, ...]:
    out = [0.0] * n_flows
    for piece, weight in entries:
        out[piece] = max(out[piece], abs(weight))
    return tuple(out)


def _remat(step):
    """A scan body whose reverse pass saves only its carry (the state) and recomputes the rest:
    stacking every intermediate scalar of every step made XLA re-evaluate the step once per
    stacked residual (the stored-trajectory gradient cost ~100x the forward run, now ~3x)."""
    return jax.checkpoint(step, prevent_cse=False)


def kept_blocks(n: int, blocks: int) -> tuple[int, int, int]:
    """How a run of ``n`` steps that keeps ``blocks`` states is laid out: (blocks, steps per
    block, rest). The ``rest`` = n mod blocks steps run first, unkept, then the blocks of
    ⌊n/blocks⌋ steps, each block's last state kept. ``advance(..., keep=k)`` keeps ⌊n/k⌋ (at
    least 1): blocks of k steps, or a few more where k does not divide n, and rest < k;
    ``retrace`` reads the number from the kept trajectory's length."""
    return blocks, n // blocks, n % blocks


class Composition(AbstractFlow):
    """A composed one-step map ``step(state, h)``; itself a flow (not a group), so it can
    be a piece of another composition. Built by ``compose``.

    Shapes and dtypes: ``state`` is any PyTree the flows accept; ``h`` a real scalar, cast to
    the state's floating dtype (the state is never cast to ``h``'s). The result has the
    state's structure, shapes and dtypes.

    Traced: the flows are its PyTree children, so their array fields (inertia, rates) are
    traced wherever the step goes (``jit``, ``vmap``, ``grad``), and so are ``state`` and
    ``h``. Static: ``word`` (the merged (piece, weight) sequence), ``scheme`` and ``fsal``
    (first-same-as-last merging across steps in ``advance``). The program is the same for
    every value of the traced parts and under every transformation: nothing is chosen from
    values seen at a call.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)     # 1 + 0.5 < 2: on purpose
    >>> step = jaxsplit.splitting(body, "strang", "casimir", shift=1)
    >>> step.word, step.fsal
    (((0, 0.5), (1, 1.0), (0, 0.5)), True)
    >>> m = step(jnp.array([0.6, 0.0, 0.8]), 0.1)
    >>> m.shape, m.dtype, float(jnp.sum(m * m))
    ((3,), dtype('float64'), 1.0)
    """

    flows: tuple[AbstractFlow, ...]
    word: Word = eqx.field(static=True, converter=_whole)
    scheme: Scheme | None = eqx.field(static=True, default=None)
    fsal: bool = eqx.field(static=True, default=False)
    processing: tuple[Word, Word, Word] | None = eqx.field(static=True, default=None,  # (P, K, P⁻¹)
                                                          converter=_whole_parts)

    def __call__(self, state, h):
        return self._step(state, _like_state(h, state))

    def _step(self, state, h):
        """One step: P, K and P⁻¹ (``_parts``; a processed scheme's processor rolled,
        ``_apply_once``; the map is the word's, unmerged at the two joints: equal to round-off)."""
        pre, kernel, post = self._parts
        state = _apply_once(self.flows, pre, state, h)
        return _apply_once(self.flows, post, _apply(self.flows, kernel, state, h), h)

    @property
    def _parts(self) -> tuple[Word, Word, Word]:
        """(P, K, P⁻¹): a processed scheme's processing, else ((), word, ())."""
        return self.processing or ((), self.word, ())

    @property
    def kernel_word(self) -> Word:
        """The sub-flows repeated by a run: the word, or a processed scheme's kernel K."""
        return self._parts[1]

    @property
    def is_group(self) -> bool:
        return False

    @property
    def uses_selects(self) -> bool:
        return _guarded(self.flows)

    @property
    def keeps_a_part(self) -> bool:
        """Whether some part of the state is declared ``"fixed"`` by every flow: a loop over
        steps then returns it unchanged, and such a loop runs as plain loops, not one kernel
        (inside another loop, a user's ``lax.scan`` or a checkpointed block, XLA's one-kernel
        emitter aborted the process on it: "All or none of the slices should have an
        explicit index"; ``tests/test_adjoints.py``)."""
        parts = [getattr(f, "parts", None) for f in self.flows]
        if any(p is None for p in parts):
            return False
        return any(all(p[i] == "fixed" for p in parts) for i in range(min(map(len, parts))))

    def _loops(self):
        return plain_loops() if self.keeps_a_part else contextlib.nullcontext()

    def turn_rate(self, x):
        """The flows' bounds, each scaled by the largest weight it is called with (``reach``):
        a bound per unit step size; None unless every flow declares one."""
        rates = [f.turn_rate(x) for f in self.flows]
        if any(r is None for r in rates):
            return None
        return jnp.max(jnp.stack([r * w for r, w in zip(rates, self.reach())]))

    def entries(self) -> Word:
        """Every (piece, weight) sub-flow a call or a run may evaluate (sub-steps are weight·h),
        merges across steps included."""
        return _entries(self.word, self._parts, self.fsal)

    def reach(self) -> tuple[float, ...]:
        """The largest |weight| each piece is called with."""
        return _reach(self.entries(), len(self.flows))

    @property
    def is_reversible(self) -> bool:
        """Ψ_{−h} = Ψ_h⁻¹ (as a piece of another composition): a time-symmetric scheme of
        reversible flows."""
        return self.scheme is not None and self.scheme.symmetric and all(f.is_reversible for f in self.flows)

    def _sequences(self):
        """``advance``'s sub-flows for n steps as (head, body repeated n times, tail): the word
        alone, or with first-same-as-last merging the first sub-flow, n joints (the rest of the
        word, its last sub-flow merged with the next step's first) and that first sub-flow
        undone. Undoing it (φ_{−a}∘φ_{b+a} = φ_b: a group) instead of ending on the word's own
        tail keeps ONE copy of the word in the compiled program: XLA compiles every sub-flow
        as a kernel of its own, and a second copy doubled the compile time of long schemes
        (Kahan–Li 10 on three pieces: 7 s). The cost: one rotation per call, and round-off.
        A processed scheme's P opens the head and P⁻¹ closes the tail: n steps P⁻¹ ∘ K^n ∘ P
        (head and tail run once per call, rolled where long: ``_apply_once``)."""
        return _sequences(self._parts, self.fsal)

    def retrace(self, x_after, h, n, ct_after, kept=None):
        """The reversible adjoint's backward pass over ``n`` steps: ``advance``'s exact
        sequence of sub-flows walked backwards, each flow's ``step_back`` rebuilding the
        state before it and pulling the cotangent through it. Returns (x0, ct_x0,
        ct_parameters in ``split_parameters`` order, ct_h); memory independent of n. Needs
        reversible flows (φ_{−t} = φ_t⁻¹), not a symmetric scheme: the word is inverted
        sub-flow by sub-flow.

        ``kept`` (``advance(..., keep=k)``'s kept states, for a Python int ``n`` ≥ 2): the walk
        restarts from each kept state instead of the rebuilt one, so round-off accumulates over
        one block of steps (``kept_blocks``, read from the number kept), not over the run (the
        stored adjoint's backward pass)."""
        with self._loops():
            return self._retrace(x_after, h, n, ct_after, kept)

    def _retrace(self, x_after, h, n, ct_after, kept):
        """The body of ``retrace``."""
        h = _like_state(h, x_after)
        # one accumulator per flow, shaped as its step_back returns them (per state for a batch:
        # summed once at the end; a sum over the batch at every sub-flow cost 5 kernels a step)
        given = jax.eval_shape(lambda x, ct: [f.step_back(x, h, ct)[2:] for f in self.flows], x_after, ct_after)
        zeros = tuple(jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), g) for g in given)

        pack, unpack = _joint_layout(x_after, ct_after)

        def back_one(piece, weight, joint, acc, flows=self.flows, h=h):  # one sub-flow undone, cotangents added
            x, ct = unpack(joint)
            x, ct, dp, dt = flows[piece].step_back(x, weight * h, ct)
            grown = jax.tree_util.tree_map(jnp.add, acc[piece], (dp, weight * dt))
            return pack(x, ct), acc[:piece] + (grown,) + acc[piece + 1:]

        def back_rolled(sub_flows):  # back() with the sequence as data, as _apply_rolled
            pieces, weights = _as_arrays(sub_flows[::-1], h.dtype)
            branches = [lambda joint, acc, w, piece=piece: back_one(piece, w, joint, acc)
                        for piece in range(len(self.flows))]

            def sub_flow(carry, piece_weight):
                return jax.lax.switch(piece_weight[0], branches, *carry, piece_weight[1]), None

            return lambda carry: jax.lax.scan(sub_flow, carry, (pieces, weights))[0]

        def back(sub_flows, flows_h=(self.flows, h)):
            # as in _apply (``run_word``: barriers, and the pattern rolled); without the barriers a
            # Sofroniou–Spaletta 10 gradient (Casimir split) did not finish in 5 minutes
            one = lambda piece, weight, carry, fh: back_one(piece, weight, *carry, *fh)
            return lambda carry: run_word(tuple(reversed(sub_flows)), carry, one, flows_h, _guarded(self.flows))

        def back_once(sub_flows):  # as _apply_once
            return (back_rolled if _irregular(sub_flows) else back)(sub_flows)

        static = isinstance(n, int)
        head, body, tail = self._sequences()
        if static and n == 1:  # the step itself, as _step runs it
            head, body, tail = self._parts

        def back_steps(c, flows_h):
            return back(body, flows_h)(c)

        def loop(carry):
            if kept is None:
                return threaded(back_steps, carry, (self.flows, h), n)
            blocks, every, rest = kept_blocks(n, jax.tree_util.tree_leaves(kept)[0].shape[0])

            def from_kept(c, flows_h, x_kept):  # the kept state replaces the rebuilt one
                c = (pack(x_kept, unpack(c[0])[1]), c[1])
                return back_steps(c, flows_h) if every == 1 else threaded(back_steps, c, flows_h, every, one_call=False)

            carry = threaded(from_kept, carry, (self.flows, h), blocks, xs=kept, reverse=True)
            return threaded(back_steps, carry, (self.flows, h), rest) if rest else carry

        def walk(carry):  # the loop's kernel chosen as ``advance`` chose it (|m| is kept)
            carry = back_once(tail)(carry)
            return back_once(head)(by_angle_bound(self, x_after, h, loop, carry))

        carry = (pack(x_after, ct_after), zeros)
        if static:
            carry = walk(carry) if n else carry
        else:
            carry = jax.lax.cond(n > 0, walk, lambda c: c, carry)
        (x, ct), acc = unpack(carry[0]), carry[1]
        ct_parameters = [None if entry is None else sum_to_shape(entry, jnp.shape(p))
                         for f, (dp, _) in zip(self.flows, acc) for entry, p in zip(dp, split_parameters(f)[0])]
        return x, ct, ct_parameters, sum(jnp.sum(dt) for _, dt in acc).astype(h.dtype)

    def advance(self, state, h, n, keep: int = 0):
        """``n`` steps, merging the last sub-flow of each step with the first of the next.

        ``n`` is a Python int (a ``lax.scan``) or a traced integer (a ``fori_loop``). ``keep``
        = k ≥ 1 (Python int ``n`` ≥ 2, not differentiable): (state, the loop's state kept
        about every k steps, stacked: ⌊n/k⌋ of them, laid out by ``kept_blocks``; k = 1 (or
        True) every step's), what ``retrace(..., kept=)`` restarts from.
        """
        with self._loops():
            return self._advance(state, h, n, keep)

    def _advance(self, state, h, n, keep):
        """The body of ``advance``."""
        h = _like_state(h, state)
        static = isinstance(n, int)
        if static and n == 0:
            return state
        if static and n == 1:  # the step itself: nothing to merge
            return self._step(state, h)
        head, body, tail = self._sequences()

        def one(x, flows_h):
            flows, step = flows_h
            return _apply(flows, body, x, step)

        # the loop's kernel is chosen from the initial state (``by_angle_bound``; the bound holds
        # for the whole run); the head and tail, run once, keep the general one (one copy of them
        # to compile)
        if keep:
            blocks, every, rest = kept_blocks(n, max(1, n // keep))

            def block(x, flows_h):
                return one(x, flows_h) if every == 1 else threaded(one, x, flows_h, every, one_call=False)

            # the rest steps are a loop of their own: a second copy of the word to compile (Kahan–Li 8's
            # stored gradient at 1000 steps, 256 bodies: 3.1 s of CPU against 2.1 s). Run inside the
            # first block instead, as a loop of traced length, one top's gradient at 100003 steps made
            # XLA's one-kernel emitter abort ("All or none of the slices should have an explicit index")
            def kept_run(y):
                y = threaded(one, y, (self.flows, h), rest) if rest else y
                return threaded(block, y, (self.flows, h), blocks, keep=True)

            x = _apply_once(self.flows, head, state, h)
            x, kept = by_angle_bound(self, state, h, kept_run, x)
            return _apply_once(self.flows, tail, x, h), kept

        def loop(x):
            return repeated(one, x, (self.flows, h), n, _remat) if static else threaded(one, x, (self.flows, h), n)

        def steps(x0):
            x = _apply_once(self.flows, head, x0, h)
            return _apply_once(self.flows, tail, by_angle_bound(self, x0, h, loop, x), h)

        if static or not head:
            return steps(state)
        return jax.lax.cond(n > 0, steps, lambda x: x, state)

    @property
    def flows_per_step(self) -> int:
        """Sub-flows evaluated per step in a long run (after all merging)."""
        return len(self.kernel_word) - (1 if self.fsal else 0)


class RolledComposition(AbstractFlow):
    """The same map as a ``Composition``, its word run by ``lax.scan`` + ``lax.switch`` with
    the pieces and weights as traced arrays. Built by ``roll``.

    Compile time no longer grows with the word, and every scheme over the same flows (padded
    to one length with identity sub-flows) shares ONE compilation: the right form for checks
    over a whole registry, sweeps and optimisation loops. The unrolled ``Composition`` runs
    faster (no switch, merging across steps); prefer it for long integrations.

    Shapes and dtypes: ``pieces`` int32 (L,), ``weights`` floating (L,) (cast to the state's
    dtype when applied); state and ``h`` as for ``Composition``. Traced: ``flows``,
    ``pieces``, ``weights``, state, ``h``; static: only L and the number of flows.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)     # 1 + 0.5 < 2: on purpose
    >>> step = jaxsplit.splitting(body, "strang", "casimir", shift=1)
    >>> rolled = jaxsplit.roll(step, 5)
    >>> rolled.pieces.tolist(), rolled.weights.tolist()
    ([0, 1, 0, 0, 0], [0.5, 1.0, 0.5, 0.0, 0.0])
    >>> m0 = jnp.array([0.6, 0.0, 0.8])
    >>> bool(jnp.allclose(rolled(m0, 0.1), step(m0, 0.1), rtol=0, atol=1e-15))
    True
    """

    flows: tuple[AbstractFlow, ...]
    pieces: jax.Array
    weights: jax.Array

    def __call__(self, state, h):
        return _apply_rolled(self.flows, self.pieces, self.weights, state, _like_state(h, state))

    @property
    def is_group(self) -> bool:
        return False


def roll(composition: Composition, length: int | None = None) -> RolledComposition:
    """``composition`` as a ``RolledComposition``, padded to ``length`` sub-flows (static; default:
    its own word length) with identity sub-flows (piece 0, weight 0).

    Every scheme rolled to the same length over the same flows shares one compilation, and
    ``jax.vmap`` runs stacked ``pieces``/``weights`` of many schemes at once.

    >>> import jax, jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.RigidBody([2.0, 1.0, 0.5], allow_nonphysical=True)
    >>> steps = [jaxsplit.roll(jaxsplit.splitting(body, s, "casimir", shift=1), 40)
    ...          for s in ("strang", "suzuki-5", "kahan-li-6")]
    >>> pieces, weights = jnp.stack([s.pieces for s in steps]), jnp.stack([s.weights for s in steps])
    >>> run = jax.vmap(lambda p, w: jaxsplit.RolledComposition(steps[0].flows, p, w)(jnp.array([0.6, 0.0, 0.8]), 0.1))
    >>> run(pieces, weights).shape
    (3, 3)
    """
    if not isinstance(composition, Composition):
        raise InputError(f"roll needs a Composition, got {type(composition).__name__}")
    w = tuple(composition.word)
    length = len(w) if length is None else int(length)
    if length < len(w):
        raise InputError(f"length must be at least the word length {len(w)}, got {length}")
    return RolledComposition(composition.flows, *_as_arrays(w + ((0, 0.0),) * (length - len(w))))


def compose(flows: Sequence, scheme: "Scheme | str", params=None, *, merge_flows: bool | None = None
            ) -> Composition:
    """Compose ``flows`` by ``scheme`` into one step, a ``Composition`` ``step(state, h)``.

    ``flows`` are flow modules (``flow(state, t)``) or plain functions (``fn(state, t)``, or
    ``fn(state, t, params)`` with ``params=``), each the time-t map of one piece, in the
    order the scheme numbers them. ``scheme`` is a registered name or a ``Scheme`` (static).
    ``merge_flows``: ``None`` (default) merges adjacent sub-flows of every exact group flow
    and keeps the others apart; ``True`` asks to merge every piece (an error if one is not a
    group); ``False`` keeps every sub-flow of the scheme as written (for checking the merging,
    which must agree to round-off).

    Shapes, dtypes, traced/static: as for ``Composition``; ``params`` is a PyTree of arrays
    (traced). Nothing is computed here: the composition is built at trace time.

    >>> import jax.numpy as jnp, jaxsplit
    >>> def drift(x, t):                      # q' = p (exact, a group: may merge)
    ...     return x[0] + t * x[1], x[1]
    >>> def kick(x, t, k):                    # p' = -k q
    ...     return x[0], x[1] - t * k * x[0]
    >>> step = jaxsplit.compose([drift, jaxsplit.FunctionFlow(kick, jnp.array(1.0), with_params=True)],
    ...                         "strang")
    >>> q, p = step((jnp.array(1.0), jnp.array(0.0)), 0.1)
    >>> round(float(q), 6), round(float(p), 6)
    (0.995, -0.1)
    """
    scheme = schemes.resolve(scheme)
    flows = tuple(as_flow(f, params) for f in flows)
    if not flows:
        raise InputError("compose needs at least one flow")
    groups = [f.is_group for f in flows]
    bad = ", ".join(f"{k} ({type(f).__name__})" for k, f in enumerate(flows) if not f.is_group)
    if merge_flows is True and bad:
        raise InputError(f"merge_flows=True merges every piece, but piece {bad} is not an exact "
                         "one-parameter group (φ_s∘φ_t = φ_(s+t) fails); leave merge_flows=None")
    if merge_flows not in (None, True, False):
        raise InputError(f"merge_flows must be None, True or False, got {merge_flows!r}")
    if scheme.processed and bad:
        raise InputError(f"scheme {scheme.name!r} is processed (P⁻¹ ∘ K ∘ P), which needs every piece to be an "
                         f"exact one-parameter group for P⁻¹; piece {bad} is not: use an unprocessed scheme")
    w = word(scheme, len(flows))
    if merge_flows is not False:
        w = merge(w, groups)
    fsal = merge_flows is not False and len(w) >= 2 and w[0][0] == w[-1][0] and groups[w[0][0]]
    if not scheme.processed:
        return Composition(flows, w, scheme, fsal)
    pre, post = processor_words(scheme, len(flows))
    if merge_flows is not False:
        pre, post = merge(pre, groups), merge(post, groups)
    step = merge(pre + w + post, groups) if merge_flows is not False else pre + w + post
    return Composition(flows, step, scheme, fsal, processing=(pre, w, post))
