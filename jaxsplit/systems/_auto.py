"""``auto_splitting``: the scheme, split and step size that reach a tolerance at the least cost.

Cost model: a run costs its sub-flows (n_steps times a step's, a processor's once); every
rotation runs the same kernel whatever its angle (``so3.half_turn``). Error model: for each
candidate (scheme, split) a pilot run over a short horizon T_p measures the global error
e(h) against a tight reference at a ladder of step sizes (each step size run for its own
count, h traced: one compilation per split and word length, rolled; the ladder stops at the
round-off floor); in the asymptotic window the error constant
C = max e(h) / (h^p T_p) (p the scheme's order) and the global error is modelled as growing
linearly in time (a phase error, as splittings of integrable motions show), e(h, T) ≈ C h^p T.
The step for ``tol`` at ``t_end`` is h = (tol / (C t_end))^(1/p), never beyond the pilot's
largest step; the candidate of least modelled cost wins. The choice is a prediction: its
error at ``t_end`` is measured against references in ``tests/test_auto_scheme.py``.
"""

import inspect
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core._compose import Composition, compose, roll
from ..core._errors import InputError
from ..core._integrate import integrate
from ..core._schemes import schemes
from ..core._state import as_state, float_dtype, ravel
from ._base import AbstractSystem

CANDIDATES = ("strang", "blanes-moan-s6-prk", "kahan-li-6", "kahan-li-8", "blanes-casas-murua-8", "sofroniou-spaletta-10")
PILOT_ANGLES = 1.5 * 2.0 ** -np.arange(0, 7.5, 0.5)  # largest sub-step angle |c m| h of the pilot ladder (rad)
PILOT_TIME = 20.0  # pilot horizon in units of the fastest rotation's period / 2π (1/rate)
WINDOW = (1e3, 1e-3)  # asymptotic window: errors above 1e3 eps·|x| (round-off) and below 1e-3·|x|
FLOOR_MARGIN = 30.0  # and above 30× the smallest pilot error: the pilot's own accumulated round-off


class AutoSplitting(NamedTuple):
    """What ``auto_splitting`` chose: run ``integrate(step, x0, h, n_steps)``.

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.STANDARD_CASE.body()     # I = (2, 1, 2/3)
    >>> choice = jaxsplit.auto_splitting(body, jnp.array([0.4, -0.3, 0.8]), tol=1e-8, t_end=10.0,
    ...                                 candidates=("strang", "kahan-li-6"))
    >>> choice.scheme in ("strang", "kahan-li-6"), abs(choice.n_steps * choice.h - 10.0) < 1e-12
    (True, True)
    """

    step: object  # the Composition
    h: float
    n_steps: int
    scheme: str
    split: str
    options: dict
    predicted_error: float  # modelled global error at t_end (max norm)
    cost: float  # modelled cost: the run's sub-flows
    candidates: tuple  # one dict per (scheme, split) considered: its h, error constant, cost


def auto_splitting(system: AbstractSystem, x0, *, tol: float, t_end: float, candidates=CANDIDATES,
                   splits=None) -> AutoSplitting:
    """The scheme, split and step that reach max-norm error ``tol`` at ``t_end`` from ``x0``
    (one state, or a batch of free-body states (B, 3): the worst case counts) at the least
    modelled cost (module docstring). ``candidates``: scheme names; ``splits``: split names
    (default: every split ``system`` offers, with its automatic options).

    >>> import jax.numpy as jnp, jaxsplit
    >>> body = jaxsplit.STANDARD_CASE.body()     # I = (2, 1, 2/3)
    >>> m0 = jnp.array([0.45, 0.0, 0.89])
    >>> choice = jaxsplit.auto_splitting(body, m0, tol=1e-8, t_end=10.0)
    >>> sol = jaxsplit.integrate(choice.step, m0, choice.h, choice.n_steps)
    """
    if not isinstance(system, AbstractSystem):
        raise InputError(f"auto_splitting needs a system (e.g. jaxsplit.RigidBody), got {type(system).__name__}")
    for name, value in (("tol", tol), ("t_end", t_end)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise InputError(f"{name} must be a positive number, got {value!r}")
    x0 = as_state(x0)
    flat = np.asarray(ravel(x0)[0])
    eps = float(jnp.finfo(float_dtype(x0)).eps)
    scale = float(np.max(np.abs(flat))) or 1.0
    if tol < WINDOW[0] * eps * scale:
        raise InputError(f"tol = {tol:g} is below what {float_dtype(x0)} round-off allows here "
                         f"({WINDOW[0] * eps * scale:.1e} = 1e3 eps·max|x0|)")
    offered = tuple(system.splits()) if splits is None else tuple(splits)
    resolved = [system.resolve_split(name, **_auto_options(system, name)) for name in offered]
    names = tuple(candidates)
    for name in names:
        schemes.resolve(name)  # unknown names: one clear error

    rate = _rate(system, x0)
    pilot_time = min(float(t_end), PILOT_TIME / rate)
    counts = sorted({max(1, math.ceil(pilot_time * rate / a)) for a in PILOT_ANGLES})
    reference = _reference(system, x0, pilot_time, rate)
    rows = []
    window = (WINDOW[0] * eps * scale, WINDOW[1] * scale)
    for split, options in resolved:
        flows = system.split(split, **options)
        steps = {name: compose(flows, name) for name in names if schemes.resolve(name).pieces_allowed(len(flows))}
        for name, step in steps.items():
            hs, errors = _pilot_errors(step, x0, pilot_time, counts, reference, stop=FLOOR_MARGIN * window[0])
            rows.append(_candidate(step, step.scheme, split, options, hs, errors, pilot_time, tol, t_end, x0, window))
    if not rows:
        raise InputError(f"no candidate scheme applies to the splits {offered} of {system.name}")
    best = min(rows, key=lambda r: r["cost"])
    table = tuple({k: v for k, v in r.items() if k != "step"} for r in rows)
    return AutoSplitting(best["step"], best["h"], best["n_steps"], best["scheme"], best["split"], best["options"],
                         best["predicted_error"], best["cost"], table)


def _auto_options(system, split):
    """"auto" for every option of ``split`` that accepts it (e.g. the free body's shift)."""
    build = system.splits().get(split, None)
    params = inspect.signature(build).parameters if build is not None else {}
    return {k: "auto" for k, p in params.items() if p.default == "auto"}


def _rate(system, x0) -> float:
    """The fastest rotation rate along the motion (the system's bound, or the pieces' generators)."""
    from ..explore._batch import max_rate

    name, options = system.reference_split
    rate = float(jnp.max(max_rate(system, system.split(name, **options), x0)))
    return rate if rate > 0 and math.isfinite(rate) else 1.0


def _reference(system, x0, t, rate):
    """x(t) by Kahan–Li 10 on the reference split with sub-step angles <= 0.01 (rolled: its long
    word unrolled took most of ``auto_splitting``'s compilation)."""
    name, options = system.reference_split
    step = roll(compose(system.split(name, **options), "kahan-li-10"))
    n = max(1, math.ceil(t * rate / 0.01))
    return integrate(step, x0, t / n, n).final


def _pilot_errors(step, x0, t, counts, reference, stop=0.0):
    """(step sizes, max-norm errors at ``t``) for each step count: each run for its own count
    (the output time ``t`` with h traced, so one compilation serves every count), the step's
    kernel rolled and padded to the next power of two: candidates of similar length share a
    compilation, and none pays much for a longer one's (padded to the longest candidate, Strang
    ran 70 identity sub-flows a step beside Sofroniou–Spaletta 10). A processed scheme's run is
    P⁻¹ ∘ K^n ∘ P, as ``integrate`` runs it: P and P⁻¹ rolled on their own, once per count.
    The ladder stops after the first error below ``stop`` (the round-off floor): the larger
    counts after it only cost more and repeat round-off (a high-order scheme reaches it within
    the first third of the ladder; ``_candidate`` leaves such points out of the model)."""
    exact = ravel(reference)[0]
    hs = t / np.asarray(counts, dtype=float)
    pre, kernel, post = step._parts
    run = roll(Composition(step.flows, kernel), 1 << (len(kernel) - 1).bit_length())
    p, p_inv = (jax.jit(roll(Composition(step.flows, w))) if w else (lambda x, h: x) for w in (pre, post))
    errors = []
    for h in hs:
        x = p_inv(integrate(run, p(x0, h), float(h), ts=[t]).final, h)
        errors.append(float(jnp.max(jnp.abs(ravel(x)[0] - exact))))
        if errors[-1] < stop:
            break
    return hs[:len(errors)], np.asarray(errors)


def _candidate(step, scheme, split, options, hs, errors, pilot_time, tol, t_end, x0, window):
    p = scheme.order
    # round-off accumulated over the pilot's thousands of steps (~1e-12 in float64) would read as a
    # huge error constant at the smallest steps of a high-order scheme
    floor = max(window[0], FLOOR_MARGIN * float(np.min(errors)))
    inside = (errors > floor) & (errors < window[1])
    if np.all(errors <= floor):  # exact to round-off at every pilot step (e.g. a symmetric body)
        constant = 0.0
    elif np.any(inside):
        constant = float(np.max(errors[inside] / (hs[inside] ** p * pilot_time)))
    else:  # never asymptotic in the pilot: trust only its smallest step
        k = int(np.argmin(hs))
        constant = float(errors[k] / (hs[k] ** p * pilot_time))
    h_max = float(np.max(hs))
    h = h_max if constant == 0.0 else min(h_max, (tol / (constant * t_end)) ** (1.0 / p))
    n_steps = max(1, math.ceil(t_end / h))
    h = t_end / n_steps
    head, body, tail = step._sequences()  # the sub-flows of a run: body n_steps times, head and tail once
    cost = n_steps * len(body) + len(head + tail)
    return {"scheme": scheme.name, "split": split, "options": dict(options), "h": h, "n_steps": n_steps,
            "error_constant": constant, "predicted_error": constant * h**p * t_end,
            "cost": float(cost), "step": step}
