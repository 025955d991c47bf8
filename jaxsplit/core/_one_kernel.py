"""A stepping loop compiled into one CPU kernel, for jaxsplit's own programs only.

XLA's CPU runtime runs a ``while`` loop as one dispatched kernel per fused operation per
iteration, unless one iteration touches fewer bytes than a process-wide threshold (1 KiB
by default): then a late pass wraps the loop in a ``call`` tagged ``xla_cpu_small_call``,
compiled as one kernel. A composition step is dozens of small fused operations (13 fused
rotations a step for Blanes–Casas–Murua 8 at 256 bodies), above that threshold from a
single body with a long scheme up, and their dispatch was a quarter of the time at 256
bodies and most of it for one body (``benchmarks/results/one_kernel.md``,
``small_loops.md``). Raising the threshold for the process would change every other
program (diffrax's loops too): a library must not.

So ``one_kernel`` makes the call itself, tagged as that pass would tag it (and
``inlineable="false"``, which keeps XLA's call inliner off it), for this loop alone. The tag
is decided when the program is lowered for the CPU, where the shapes are final: a ``vmap``
of the user's has added its axis, so a batch that arrives by ``vmap`` and one passed as a
leading axis get the same decision (deciding at trace time saw one body under ``vmap`` and
left 256 vmapped bodies untagged):

* only while the loop's state is at most ``ONE_KERNEL_BYTES``: at 4096 bodies (96 KiB) it
  ties, at 16384 it loses 1.4–1.8×, as a single kernel is never split over threads;
* only where every operation inside is one the one-kernel emitter compiles: the pass's own
  exclusions (custom calls, scatter, sort, FFT, in/outfeed, replica and partition ids,
  collectives) and, for safety, dots, convolutions and random bits, which XLA may hand to
  a library or runtime call that emitter does not take (a user's flow with ``x.at[i].add``
  runs untagged), and transposes, which that emitter compiled wrongly in one measured case
  (``tests/test_one_kernel.py``: a vmapped state of parts whose kick differentiates a
  potential); a vmapped batch of states of parts therefore runs its loop untagged;
* never on another backend (a GPU compiles the loop as before).

Under differentiation JAX's partial evaluation makes a nested forward loop much slower
(the reversible adjoint's forward pass, Kahan–Li 8 on 256 bodies: a gradient 4× slower,
1.2 s against 0.31 s, every select test moved out as loop state), so that pass traces its
loop inside ``_loops.plain_loops``; its backward pass keeps the call (as fast as the plain loop).

``ONE_KERNEL_BYTES = -1`` turns the tag off (read at lowering: new programs only).
Untagged, the loop is the same nested ``jit``, inlined by XLA: the program it was before.
``tests/test_one_kernel.py`` fails loudly if a JAX or XLA upgrade stops honouring the tag.
"""

import jax
import numpy as np
from jax.interpreters import ad, batching, mlir

try:
    from jax.extend.core import Primitive
except ImportError:  # JAX before jax.extend.core
    from jax.core import Primitive

ONE_KERNEL_BYTES = 64 * 2**10
TAGS = {"xla_cpu_small_call": "true", "inlineable": "false"}

# stablehlo operations the one-kernel emitter cannot compile (XLA's small-while-loop pass
# refuses such loops), and for safety dots, convolutions, random bits, tokens and composites
# (whose decompositions this walk does not follow): see the module docstring
_REFUSED = ("custom_call", "scatter", "sort", "fft", "infeed", "outfeed", "partition_id", "replica_id",
            "all_reduce", "all_gather", "all_to_all", "reduce_scatter", "collective_permute",
            "collective_broadcast", "send", "recv", "dot", "dot_general", "convolution", "rng",
            "rng_bit_generator", "after_all", "create_token", "composite")
# a transpose iterated by the loop: under jit(vmap(...)) a gravity-gradient step (a kick whose
# force is jax.grad of a quadratic potential) compiled as one kernel gave wrong numbers (0.27
# after 400 steps; exact untagged, under jit alone, and written without the transpose). A
# transpose before or after the loop (vmap's batch axis moved once) is left alone.
_REFUSED_IN_LOOP = ("transpose",)
_DIALECTS = ("stablehlo.", "chlo.", "func.")


def one_kernel(loop, *args, kept: bool = False):
    """``loop(*args)`` (a ``lax.scan`` or ``while_loop`` of a step) as one call, tagged on the
    CPU to compile into one kernel where that is faster (see the module docstring). ``kept``:
    ``loop`` returns (state, byproduct), a trajectory stacked by the loop: only the state is
    weighed against ``ONE_KERNEL_BYTES`` (the byproduct is written, never iterated on)."""
    out = jax.jit(loop)(*args)
    out, byproduct = out if kept else (out, None)
    leaves, tree = jax.tree_util.tree_flatten(out)
    out = jax.tree_util.tree_unflatten(tree, _one_kernel_p.bind(*leaves))
    return (out, byproduct) if kept else out


def one_kernel_jvp(loop, primals, tangents):
    """``jax.jvp(loop, primals, tangents)`` as one call whose primal and tangent outputs are
    each tagged (the JVP of a differentiated stepping loop). Under reverse mode JAX splits the
    call into its primal part (tagged as it is) and its tangent part, whose transpose, the
    backward loop, is tagged by the primitive's transpose: the gradient's loops compile as
    one kernel each, as the forward run's does (a stored-trajectory gradient of one body ran
    20× its forward run as XLA's dispatched loop, ~3× as one kernel)."""
    # the tangents pass the primitive on their way in too: in the transposed program that
    # binding comes after the backward loop, whose call it then tags
    flat, flat_tree = jax.tree_util.tree_flatten(tangents)
    tangents = jax.tree_util.tree_unflatten(flat_tree, _one_kernel_p.bind(*flat))
    out, out_dot = jax.jit(lambda p, t: jax.jvp(loop, p, t))(primals, tangents)
    leaves, tree = jax.tree_util.tree_flatten(out)
    dots, dot_tree = jax.tree_util.tree_flatten(out_dot)
    return (jax.tree_util.tree_unflatten(tree, _one_kernel_p.bind(*leaves)),
            jax.tree_util.tree_unflatten(dot_tree, _one_kernel_p.bind(*dots)))


_one_kernel_p = Primitive("jaxsplit_one_kernel")
_one_kernel_p.multiple_results = True
_one_kernel_p.def_impl(lambda *xs: xs)
_one_kernel_p.def_abstract_eval(lambda *avals: avals)
batching.primitive_batchers[_one_kernel_p] = lambda args, dims: (_one_kernel_p.bind(*args), dims)
# linear (the identity): tangents and cotangents pass through it, and so does the tag, to the
# call that produces them
def _jvp(primals, tangents):
    tangents = [ad.instantiate_zeros(t) for t in tangents]
    return _one_kernel_p.bind(*primals), _one_kernel_p.bind(*tangents)


def _transpose(cts, *args):
    return _one_kernel_p.bind(*[ad.instantiate_zeros(ct) for ct in cts])


ad.primitive_jvps[_one_kernel_p] = _jvp
ad.primitive_transposes[_one_kernel_p] = _transpose


def _state_bytes(avals) -> int:
    return sum(int(np.prod(a.shape)) * np.dtype(a.dtype).itemsize for a in avals)


def _operations(op, in_loop: bool = False):
    """(operation, whether it sits inside a ``while`` loop) for every operation nested in ``op``."""
    for region in op.regions:
        for block in region.blocks:
            for inner in block.operations:
                yield inner, in_loop
                yield from _operations(inner, in_loop or inner.operation.name == "stablehlo.while")


def _moves_no_data(op) -> bool:
    """A transpose that only moves axes of length 1 (a reshape: what ``vmap`` puts in a loop
    over one state of several parts)."""
    try:
        shape = mlir.ir.RankedTensorType(op.operands[0].type).shape
        permutation = list(mlir.ir.DenseI64ArrayAttr(op.attributes["permutation"]))
    except Exception:  # noqa: BLE001 -- not the op this reads: refused
        return False
    kept = [axis for axis in permutation if shape[axis] != 1]
    return kept == sorted(kept)


def _compilable(function, symbols, seen, in_loop: bool = False) -> bool:
    """Every operation reachable from ``function`` (through calls) is one the one-kernel
    emitter compiles (``_REFUSED``; ``_REFUSED_IN_LOOP`` only where a loop iterates it)."""
    for op, looped in _operations(function, in_loop):
        name = op.operation.name
        short = name.split(".", 1)[1] if "." in name else name
        if not name.startswith(_DIALECTS) or short in _REFUSED or (
                looped and short in _REFUSED_IN_LOOP and not _moves_no_data(op)):
            return False
        if name == "func.call":
            callee = mlir.ir.FlatSymbolRefAttr(op.attributes["callee"]).value
            if (callee, looped) not in seen:
                seen.add((callee, looped))
                if not _compilable(symbols[callee], symbols, seen, looped):
                    return False
    return True


def _call_to_tag(ctx, values):
    """The ``func.call`` producing ``values`` if the loop should run as one kernel, else None
    (values made elsewhere, such as the zero cotangent of an input the loop does not use,
    are no call's: one call among the owners is the loop's)."""
    owners = {None if isinstance(v.owner, mlir.ir.Block) else v.owner.operation for v in values}
    calls = [op for op in owners if op is not None and op.name == "func.call"]
    if len(calls) != 1 or _state_bytes(ctx.avals_in) > ONE_KERNEL_BYTES:
        return None
    call = calls[0]
    callee = mlir.ir.FlatSymbolRefAttr(call.attributes["callee"]).value
    symbols = ctx.module_context.symbol_table
    return call if _compilable(symbols[callee], symbols, {(callee, False)}) else None


def _tag_on_cpu(ctx, *values):
    try:
        call = _call_to_tag(ctx, values)
    except Exception:  # noqa: BLE001 -- an IR this code does not know (another JAX): untagged, as before
        call = None
    if call is not None:
        attributes = call.attributes
        existing = ({a.name: a.attr for a in mlir.ir.DictAttr(attributes["mhlo.frontend_attributes"])}
                    if "mhlo.frontend_attributes" in attributes else {})
        tags = {k: mlir.ir.StringAttr.get(v) for k, v in TAGS.items()}
        attributes["mhlo.frontend_attributes"] = mlir.ir.DictAttr.get(existing | tags)
    return values


mlir.register_lowering(_one_kernel_p, lambda ctx, *values: values, cacheable=False)
mlir.register_lowering(_one_kernel_p, _tag_on_cpu, platform="cpu", cacheable=False)
