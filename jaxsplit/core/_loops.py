"""The loops that run a composition's steps, and the layout rotations may use inside them.

A rotation of a batch laid out components last (``so3._with_components``) is fastest as a
``select`` on the component index: XLA keeps a state's three components in one loop
iteration, where LLVM evaluates the rotation's polynomial once. The select's component tests
are constants, and they must stay inside the kernel for LLVM to resolve them. XLA's
loop-invariant code motion hoists them out of any loop whose state holds a value the body
passes on unchanged (a closed-over parameter, h: every ``lax.scan`` that closes over traced
values); the tests then enter each kernel as data and it runs as scalar code (256 bodies,
Blanes–Casas–Murua 8: 22.7 ms instead of 17.2, slower than the ``stack`` form at 19.3).

So the select form is used only where that cannot happen: in the body of ``threaded``, which
carries the values the body needs (the invariants) through an optimization barrier together
with the state, and for a traced count its bound as well (a ``fori_loop`` carries it unchanged:
output at given times ran 19× slower), so nothing in the loop's state is unchanged. Everywhere else (a user's own
``scan``, diffrax's loop, a differentiated run) rotations use the ``stack`` form.

``threaded`` also runs its loop through ``one_kernel``: a call XLA compiles as one CPU kernel
where that is faster (``_one_kernel``).

On an accelerator both CPU devices fail: the select form leaves each rotation as two kernels
(its components, then the select that writes them back into the (B, 3) array), and a
components-last batch is read with a stride of three. There ``threaded`` carries the state
components first (every batched array leaf as one array per component, ``laid_out``), so that
a flow's components are contiguous arrays and XLA fuses a step into one elementwise kernel;
the body still sees components last (a ``stack`` whose slices XLA folds away). Measured on an H200
(``benchmarks/results/throughput-gpu.md``): Strang on 10⁶ free bodies ran 4.4× slower than a
hand-fused loop over three component arrays with the CPU's form.
"""

import contextlib
import contextvars
import functools

import equinox as eqx
import jax
import jax.numpy as jnp

from ._angles import assuming, short_angles
from ._one_kernel import one_kernel, one_kernel_jvp

_SELECTS = contextvars.ContextVar("jaxsplit_selects", default=False)
_PLAIN = contextvars.ContextVar("jaxsplit_plain_loops", default=False)
_FIRST = contextvars.ContextVar("jaxsplit_components_first", default=None)


@contextlib.contextmanager
def _set(var, value):
    token = var.set(value)
    try:
        yield
    finally:
        var.reset(token)


def _switched_on(flag):
    return _set(flag, True)


def selects() -> bool:
    """Whether the rotation being traced may use the select form (inside ``threaded``)."""
    return _SELECTS.get()


def plain_loops():
    """Loops ``threaded`` traces inside run as plain loops, not through ``one_kernel``."""
    return _switched_on(_PLAIN)


def components_first(on: bool = True):
    """Loops traced inside carry their state components first (``True``) or components last
    (``False``) whatever the backend; by default, components first on an accelerator only."""
    return _set(_FIRST, on)


def laid_out() -> bool:
    """Whether ``threaded`` carries its state components first (the module docstring)."""
    first = _FIRST.get()
    return jax.default_backend() != "cpu" if first is None else first


class _Rows(eqx.Module):
    """A batched leaf carried as its components, one array each (``laid_out``)."""

    rows: tuple


def _split(tree):
    """Every array leaf of ``tree`` with a batch (two axes or more) as ``_Rows`` of its last
    axis; a state module (``eqx.Module``: the spin lattices' ``Components``) lays itself out
    and is passed through."""
    def split(a):
        if isinstance(a, eqx.Module) or jnp.ndim(a) < 2:
            return a
        return _Rows(tuple(a[..., k] for k in range(jnp.shape(a)[-1])))

    return jax.tree.map(split, tree, is_leaf=lambda a: isinstance(a, eqx.Module))


def _join(tree):
    """``_split``'s inverse (also for kept carries, which have a leading axis more)."""
    return jax.tree.map(lambda a: jnp.stack(a.rows, axis=-1) if isinstance(a, _Rows) else a, tree,
                        is_leaf=lambda a: isinstance(a, _Rows))


def threaded(body, carry, invariants, n, one_call: bool = True, keep: bool = False, xs=None, reverse: bool = False):
    """``n`` times ``carry = body(carry, invariants)``: a ``lax.scan`` (Python int ``n``) or a
    ``while_loop`` (traced ``n``), the array leaves of ``invariants`` (and a traced bound)
    carried through an optimization barrier with ``carry`` (the module docstring says why),
    the body traced with the select form on; through ``one_kernel`` unless ``plain_loops`` or
    ``one_call`` is False (a loop nested in another's kernel).

    For a Python int ``n`` only: ``keep`` returns (carry, the carries after each iteration
    stacked); ``xs`` (leading axis ``n``) gives iteration k its slice, ``body(carry, invariants,
    x_k)``; ``reverse`` runs the iterations from the last slice to the first."""
    arrays, rest = eqx.partition(invariants, eqx.is_array)
    if not laid_out():
        return _threaded(body, carry, arrays, rest, n, one_call, keep, xs, reverse, False)
    return _join(_threaded(body, _split(carry), arrays, rest, n, one_call, keep, xs, reverse, True))


def _threaded(body, carry, arrays, rest, n, one_call, keep, xs, reverse, first):
    def through(c, *x):
        state, inv = c
        if first:
            state = _join(state)
        with _switched_on(_SELECTS) if not (_PLAIN.get() or first) else contextlib.nullcontext():
            state = body(state, eqx.combine(inv, rest), *x)
        if first:
            state = _split(state)
        return jax.lax.optimization_barrier((state, inv))

    run = one_kernel if one_call else (lambda loop, *args, kept=False: loop(*args))
    if isinstance(n, int):
        def scanned(c, xs):
            def one(c, x):
                c = through(c, *(() if xs is None else (x,)))
                return c, (c[0] if keep else None)

            c, kept = jax.lax.scan(one, c, xs, length=n, reverse=reverse)
            return (c[0], kept) if keep else c[0]

        return run(scanned, (carry, arrays), xs, kept=keep)
    # a traced count: a while loop whose bound goes through the barrier too (a fori_loop carries
    # it unchanged, and XLA then hoisted the select's tests: ts= runs 7x slower). Closed over,
    # not passed: a concrete n stays concrete (passed in, one body's reversible gradient 6 % slower)
    def counted(c):
        def again(k_c_bound):
            return k_c_bound[0] < k_c_bound[2]

        def one(k_c_bound):
            k, c, bound = k_c_bound
            c, bound = jax.lax.optimization_barrier((through(c), bound))
            return k + 1, c, bound

        bound = jnp.asarray(n)
        return jax.lax.while_loop(again, one, (jnp.zeros((), bound.dtype), c, bound))[1][0]

    return run(counted, (carry, arrays))


def repeated(body, carry, invariants, n: int, remat=lambda f: f):
    """``threaded`` for a Python int ``n``, differentiated as the plain ``lax.scan`` whose body
    (wrapped in ``remat``) closes over the invariants: carried, reverse mode would save them at
    every step."""
    arrays, rest = eqx.partition(invariants, eqx.is_array)
    return _repeated(lambda y, inv: body(y, eqx.combine(inv, rest)), remat, carry, arrays, n, _PLAIN.get(),
                     short_angles())


# ``plain`` is ``plain_loops`` at the call and ``limit`` the kernel's ``short_angles``, kept for
# the JVP rule: JAX may apply it after the call has been traced (``grad`` of a ``jit``, a
# ``cond``'s branch), outside those contexts
@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 4, 5, 6))
def _repeated(body, remat, carry, arrays, n, plain, limit):
    return threaded(body, carry, arrays, n)


@_repeated.defjvp
def _repeated_jvp(body, remat, n, plain, limit, primals, tangents):
    def closed(carry, arrays):
        step = remat(lambda y: body(y, arrays))
        return jax.lax.scan(lambda y, _: (step(y), None), carry, length=n)[0]

    with assuming(limit):
        if plain or _PLAIN.get():
            return jax.jvp(closed, primals, tangents)
        return one_kernel_jvp(closed, primals, tangents)
