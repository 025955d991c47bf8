"""Linear stability of a splitting at equilibria, against the exact linearisation.

At an equilibrium x* of the flow (a fixed point of every splitting map built from its
exact pieces, e.g. the free body's steady rotations m = e_i) the map's Jacobian DΦ
(``jax.jacfwd``) leaves the tangent space of the symplectic leaf, range Π(x*), invariant:
a Poisson map preserves Π, so DΦ Π(x*) DΦᵀ = Π(x*). With U an orthonormal basis of that
range and V of its complement (SVD of Π(x*)), DΦ is block triangular in (U, V): the
*leaf block* B = Uᵀ DΦ U carries the dynamics on the leaf (symplectic there: det B = 1),
the *transverse block* Vᵀ DΦ V the Casimir directions (eigenvalues 1). The map is linearly
stable when every eigenvalue of B has modulus <= 1 + ``tol``: for a 2-dimensional leaf
(the free body) e^{±iθ} while |tr B| < 2 (elliptic), real μ, 1/μ beyond (hyperbolic).

The exact flow linearised at x*, A = D(Π∇H)(x*), restricted to the leaf has eigenvalues λ;
the exact time-h map has e^{hλ}, spectral radius e^{h max Re λ}. For the free body at e_1
(w = 1/I), λ² = (w_1 − w_3)(w_2 − w_1) and in general (w_i − w_a)(w_b − w_i): elliptic for
the largest and smallest moment, hyperbolic for the middle one. A discrete map can lose
stability where the flow is stable (a resonance once the rotation per step gets large) or
gain a spurious stability where it is not; ``stability_map`` locates both on a grid of
(h, parameters).
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..core._compose import roll
from ..core._errors import InputError
from ..core._schemes import schemes
from ..core._state import ravel
from ..systems._splitting import splitting
from ._batch import build, compiled, family_of, resolved_groups, take

STABILITY_TOL = 1e-9  # spectral radius above 1 + this counts as unstable


def _leaf_basis(pi, rank: int):
    """Orthonormal bases (U of range Π, V of its complement) from the SVD of Π."""
    u, _, _ = jnp.linalg.svd(pi)
    return u[:, :rank], u[:, rank:]


def _kernel(family, scheme, split, options: tuple, rank: int, equilibria):
    options = dict(options)

    def one(h, params):
        system = family(params)
        step = roll(splitting(system, scheme, split, **options))

        def at(x):
            flat, unravel = ravel(x)
            hh = jnp.asarray(h, flat.dtype)
            jac = jax.jacfwd(lambda v: ravel(step(unravel(v), hh))[0])(flat)
            field = jax.jacfwd(lambda v: ravel(system.vector_field(unravel(v)))[0])(flat)
            u, v = _leaf_basis(system.poisson_matrix(x), rank)
            fixed = jnp.max(jnp.abs(ravel(step(x, hh))[0] - flat))
            return u.T @ jac @ u, v.T @ jac @ v, u.T @ field @ u, fixed

        # every equilibrium through one traced program (a loop over them traced it once each)
        return jax.vmap(at)(_equilibria(system, equilibria))

    return jax.vmap(jax.vmap(one, in_axes=(None, 0)), in_axes=(0, None))


def _equilibria(system, equilibria):
    """The equilibria as one PyTree with a leading axis E."""
    return system.equilibria() if equilibria is None else equilibria(system)


def _equilibrium_list(system, equilibria):
    xs = _equilibria(system, equilibria)
    count = len(jax.tree_util.tree_leaves(xs)[0])
    return [take(xs, k) for k in range(count)]


def _leaf_rank(system, equilibria, tol=1e-10) -> int:
    ranks = set()
    for x in _equilibrium_list(system, equilibria):
        s = np.linalg.svd(np.asarray(system.poisson_matrix(x)), compute_uv=False)
        ranks.add(int(np.sum(s > tol * max(s.max(), 1e-300))))
    if len(ranks) != 1 or ranks == {0}:
        raise InputError(f"the equilibria lie on symplectic leaves of different or zero dimension {sorted(ranks)}")
    return ranks.pop()


def stability_map(scheme, step_sizes, params, *, system=None, split: str | None = None, equilibria=None,
                  tol: float = STABILITY_TOL, allow_nonphysical: bool = False, **split_options) -> dict:
    """Linear stability at the equilibria for every (h, parameters); arrays (n_h, n_params, E, ...).

    ``system`` is a family params -> system (default ``RigidBody``: ``params`` are inertias
    (n, 3), the equilibria m = e_1, e_2, e_3; ``allow_nonphysical`` admits non-physical ones,
    as for ``RigidBody``); ``equilibria`` a function system -> states
    with a leading axis E (default ``system.equilibria()``). Returns ``eigenvalues`` of DΦ
    (complex; the transverse ones first, then the leaf's), ``leaf_eigenvalues``,
    ``spectral_radius`` (on the leaf), ``trace`` and ``det`` of the leaf block (det = 1 for
    a Poisson map), ``stable``; the exact flow's ``exact_eigenvalues``,
    ``exact_spectral_radius``, ``exact_stable``; ``fixed_point_error`` (max|Φ(x*) − x*|);
    for 2-dimensional leaves ``angle`` (rotation per step, NaN where hyperbolic) and
    ``exact_angle``; ``first_unstable_h`` (n_params, E): the smallest grid h at which the map
    is unstable where the exact flow is stable (NaN if none), and ``first_spurious_h``: the
    smallest grid h at which the map is stable where the flow is not. NumPy arrays; the
    parameters and step sizes are traced (one compilation), the scheme and split static.

    >>> import jaxsplit
    >>> out = jaxsplit.stability_map("strang", [0.1, 1.0], [[1.0, 2.0, 3.0]], split="casimir", shift=1)
    >>> out["stable"].shape, out["exact_stable"][0, 0].tolist()           # axes 0 and 2 stable, 1 not
    ((2, 1, 3), [True, False, True])
    """
    scheme = schemes.resolve(scheme)
    family = family_of(system, allow_nonphysical)
    h = np.atleast_1d(np.asarray(step_sizes, dtype=float))
    if h.ndim != 1 or len(h) == 0 or not np.all(np.isfinite(h) & (h > 0)):
        raise InputError(f"step_sizes must be positive finite numbers, got {np.asarray(step_sizes).tolist()}")
    params = jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=float), params)
    if system is None:
        params = np.atleast_2d(params)
        if params.ndim != 2 or params.shape[1] != 3 or not np.all(np.isfinite(params) & (params > 0)):
            raise InputError(f"inertias must be positive, shape (n, 3); got shape {params.shape}")
    if not (isinstance(tol, float) and tol >= 0):
        raise InputError(f"tol must be a float >= 0, got {tol!r}")
    build(family, params)  # validates the concrete batch
    dtype = np.result_type(h.dtype, *[a.dtype for a in jax.tree_util.tree_leaves(params)], jnp.result_type(float))
    h = h.astype(dtype)
    params = jax.tree_util.tree_map(lambda a: a.astype(dtype), params)
    n_params = len(jax.tree_util.tree_leaves(params)[0])
    rank = _leaf_rank(build(family, take(params, 0)), equilibria)

    blocks = None
    for name, opts, idx in resolved_groups(family, params, split, split_options):
        key = tuple(sorted(opts.items()))
        fn = compiled(("stability", family, scheme, name, key, rank, equilibria),  # a later map reuses it
                      lambda name=name, key=key: _kernel(family, scheme, name, key, rank, equilibria), None)
        part = [np.asarray(r) for r in fn(jnp.asarray(h), take(params, idx))]
        if blocks is None:
            blocks = [np.empty((len(h), n_params) + p.shape[2:], p.dtype) for p in part]
        for b, p in zip(blocks, part):
            b[:, idx] = p
    leaf, transverse, exact_leaf, fixed = blocks

    leaf_eigs = np.linalg.eigvals(leaf)
    eigenvalues = np.concatenate([np.linalg.eigvals(transverse) if transverse.shape[-1] else
                                  np.zeros(transverse.shape[:-1], complex), leaf_eigs], axis=-1)
    radius = np.max(np.abs(leaf_eigs), axis=-1)
    lam = np.linalg.eigvals(exact_leaf)
    hh = h[:, None, None, None]
    exact_eigs = np.exp(hh * lam)
    growth = np.max(lam.real, axis=-1)
    exact_radius = np.exp(h[:, None, None] * growth)
    stable = radius <= 1 + tol
    exact_stable = exact_radius <= 1 + tol
    trace = np.trace(leaf, axis1=-2, axis2=-1)
    det = np.linalg.det(leaf)

    order = np.argsort(h)

    def first(mask):
        hit = np.any(mask, axis=0)
        return np.where(hit, h[order][np.argmax(mask, axis=0)], np.nan)

    out = {
        "step_sizes": h, "params": params, "eigenvalues": eigenvalues, "leaf_eigenvalues": leaf_eigs,
        "spectral_radius": radius, "trace": trace, "det": det, "stable": stable,
        "exact_eigenvalues": exact_eigs, "exact_spectral_radius": exact_radius, "exact_stable": exact_stable,
        "fixed_point_error": fixed,
        "first_unstable_h": first((~stable & exact_stable)[order]),
        "first_spurious_h": first((stable & ~exact_stable)[order]),
    }
    if system is None:
        out["inertias"] = params
    if rank == 2:
        with np.errstate(invalid="ignore"):
            out["angle"] = np.where(np.abs(trace) <= 2, np.arccos(np.clip(trace.real / 2, -1, 1)), np.nan)
        out["exact_angle"] = np.where(exact_stable, h[:, None, None] * np.max(np.abs(lam.imag), axis=-1), np.nan)
    return out
