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

On an accelerator the select form is slower: XLA's GPU compiler leaves each rotation as two
kernels there (its components, then the select that writes them back into the (B, 3) array).
Loops use the stack form on every backend but the CPU (``select_form``). Measured on an H200
(``benchmarks/results/gpu_layout-gpu.md``, Strang, 10⁶ free bodies, 2,000 steps, under
``jit(vmap)``): 1.15e4 million body-steps/s with the select form, 4.1e4 with the stack form,
against 9.0e4 for a hand-fused loop over three component arrays. Carrying the loop's state
as one array per component was slower (2.0e4 for the direct call), and a transposed (3, B)
carry too (``throughput-gpu-7ae3756.md``).
"""

import contextlib
import contextvars
import functools

import equinox as eqx
import jax
import jax.numpy as jnp

from ._angles import assuming, setting, short_angles
from ._one_kernel import one_kernel, one_kernel_jvp

_SELECTS = contextvars.ContextVar("jaxsplit_selects", default=False)
_PLAIN = contextvars.ContextVar("jaxsplit_plain_loops", default=False)
_FORM = contextvars.ContextVar("jaxsplit_select_form", default=None)


def _switched_on(flag):
    return setting(flag, True)


def selects() -> bool:
    """Whether the rotation being traced may use the select form (inside ``threaded``)."""
    return _SELECTS.get()


def plain_loops():
    """Loops ``threaded`` traces inside run as plain loops, not through ``one_kernel``."""
    return _switched_on(_PLAIN)


def select_form(on: bool = True):
    """Rotations traced inside jaxsplit's loops use the select form (``True``) or the stack form
    (``False``) whatever the backend; by default the select form on the CPU only (the module
    docstring)."""
    return setting(_FORM, on)


def _selecting() -> bool:
    form = _FORM.get()
    return jax.default_backend() == "cpu" if form is None else form


def threaded(body, carry, invariants, n, one_call: bool = True, keep: bool = False, xs=None, reverse: bool = False):
    """``n`` times ``carry = body(carry, invariants)``: a ``lax.scan`` (Python int ``n``) or a
    ``while_loop`` (traced ``n``), the array leaves of ``invariants`` (and a traced bound)
    carried through an optimization barrier with ``carry`` (the module docstring says why),
    the body traced with the select form on the CPU (``select_form``); through ``one_kernel`` unless ``plain_loops`` or
    ``one_call`` is False (a loop nested in another's kernel).

    For a Python int ``n`` only: ``keep`` returns (carry, the carries after each iteration
    stacked); ``xs`` (leading axis ``n``) gives iteration k its slice, ``body(carry, invariants,
    x_k)``; ``reverse`` runs the iterations from the last slice to the first."""
    arrays, rest = eqx.partition(invariants, eqx.is_array)
    selecting = _selecting() and not _PLAIN.get()

    def through(c, *x):
        state, inv = c
        with _switched_on(_SELECTS) if selecting else contextlib.nullcontext():
            state = body(state, eqx.combine(inv, rest), *x)
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
