"""Fitting a spin lattice's couplings to an observed trajectory or an observed S(q, ω): a case
of the generic ``fit`` (``_fit``), differentiating through the exact bond splitting.

The family
----------
``SpinCouplings`` is a family ``params -> SpinLattice`` (hashable: one compilation per lattice,
bond classes and choice of fitted terms). ``params`` holds the fitted terms among

* ``exchange`` J (C,) and ``anisotropic`` Δ (C,), one per bond class, ``dm`` D (C, 3);
* ``anisotropy`` K () (shared by every site, along the fixed ``axis`` n), ``field`` B (3,),
  or a number b for B = b n (the field along the axis: what a spectrum about an ordered
  state along n determines well; its transverse components enter S(q, ω) only weakly);

every other term is held at its ``fixed`` value. The bond classes (``bond_classes``) are
the bond directions of a named lattice (square: x and y bonds; honeycomb: three), or one
class for every bond (``"all"``), or any integer label per bond.

What is compared
----------------
* ``target="trajectory"``: the spins S_i(t_k) themselves (the generic ``fit``'s residuals);
  the model starts from ``x0`` (default: the first observation, rescaled to |S_i| = s_i).
* ``target="structure-factor"``: S(q, ω) of the predicted trajectory (``structure_factor``
  at the observation times, which must be equally spaced), both it and the data broadened
  in ω by a Gaussian of width ``resolution`` (an instrument resolution: it widens the
  basin of the fit; the optimum of noise-free data does not move) and divided by the
  data's largest intensity. The model starts from the given ``x0`` (the state the data were
  taken from: a perturbed ordered state, or a thermal sample drawn the same way).

Gradients go through the integrator with the reversible adjoint by default
(``adjoint="reversible"``: memory flat in the steps per observation; ``"checkpoint"`` keeps
each interval's steps while differentiating it). Adam, then L-BFGS (``_fit.minimise``).

Identifiability and the gauge
-----------------------------
Exact symmetries of the data (nothing fitted can decide them; each is stated in
``CouplingFit.gauge``):

* **Units.** Ṡ_i = ∂H/∂S_i × S_i with ħ = 1: couplings are angular frequencies in the
  inverse unit of the data's time axis. Scaling every coupling by λ and time by 1/λ gives
  the same data; the time axis fixes it.
* **Sign (S(q, ω) only).** The global flip S_i → −S_i maps solutions of
  (J, Δ, D, K, B) onto solutions of (−J, −Δ, −D, −K, B) (the quadratic terms' fields are odd
  in S, the Zeeman field is not), and S(q, ω) is quadratic in δS: a ferromagnet's spectrum
  from x0 is an antiferromagnet's from −x0, exactly (``flipped``; tested). The spectrum
  fixes the couplings' sign only together with the initial state's; the gauge here is the
  given ``x0``. A trajectory observes S itself, so it fixes the sign.

Directions the particular data leave (nearly) free show as small eigenvalues of the
Gauss–Newton Hessian JᵀJ (``ParameterFit.hessian_eigenvalues``): below ``NULL_RATIO``
times the largest a combination is reported as undetermined, below ``WEAK_RATIO`` as weak
(``CouplingFit.undetermined`` / ``weak``, with its coefficients by parameter name). Known
cases: a collinear state (every S_i ∥ n ∥ B) does not move, so no coupling shows; a small
precession about a ferromagnet along n ∥ B sees B and K only as the gap B + 2Ks (to
O(θ²) in the cone angle θ, so K's own eigenvalue is O(θ⁴) of B's); in a pure Heisenberg
model the field only adds a global precession, which a trajectory sees but S^{zz}(q, ω)
along B does not (``components="z"``). Fix such a term (``fixed=``) to the value known
from elsewhere, or take data that move it (larger amplitude, other components).
"""

import dataclasses
import math
import time
from typing import NamedTuple

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..lattices._graph import Lattice
from ..measure._structure_factor import structure_factor
from ..systems._spin_lattice import SpinLattice
from ._fit import fit, positive

TERMS = ("exchange", "anisotropic", "dm", "anisotropy", "field")
PER_CLASS = ("exchange", "anisotropic", "dm")
TARGETS = ("trajectory", "structure-factor")
NULL_RATIO = 1e-12  # a Gauss–Newton eigenvalue below this fraction of the largest: undetermined
WEAK_RATIO = 1e-6  # below this fraction: weakly determined (reported, still fitted)


# ------------------------------------------------------------------ bond classes
def bond_classes(lattice: Lattice, by="direction") -> tuple:
    """(labels (B,) int, names) of the bonds of ``lattice``: ``"direction"`` (a named lattice's
    bond vectors, minimum image in the periodic box: the square lattice's x and y bonds are
    two classes), ``"all"`` (one class), or an integer array (B,) of your own labels.

    >>> import jaxsplit
    >>> from jaxsplit.explore._fit_spins import bond_classes
    >>> labels, names = bond_classes(jaxsplit.lattices.lattice("square", 4))
    >>> labels.shape, names
    ((32,), ('(1,0)', '(0,1)'))
    """
    if not isinstance(lattice, Lattice):
        raise InputError(f"bond classes need a lattice (jaxsplit.lattices.lattice(...)), got {type(lattice).__name__}")
    if isinstance(by, str):
        if by == "all" or (by == "direction" and lattice.cell is None):
            return np.zeros(lattice.n_bonds, np.int64), ("all",)
        if by != "direction":
            raise InputError(f"bond classes must be 'direction', 'all' or one integer label per bond, got {by!r}")
        d = lattice.positions[lattice.bonds[:, 1]] - lattice.positions[lattice.bonds[:, 0]]
        if lattice.periodic:
            box = lattice.cell * np.asarray(lattice.size, float)[:, None]
            frac = d @ np.linalg.inv(box)
            d = (frac - np.round(frac)) @ box
        keys = [tuple(np.round(v, 6) + 0.0) for v in d]
        order = list(dict.fromkeys(keys))
        labels = np.array([order.index(k) for k in keys], np.int64)
        names = tuple("(" + ",".join(f"{x:.4g}" for x in k) + ")" for k in order)
        return labels, names
    labels = np.asarray(by)
    if labels.shape != (lattice.n_bonds,) or not np.issubdtype(labels.dtype, np.integer) or labels.min() < 0:
        raise InputError(f"bond classes must be {lattice.n_bonds} integer labels >= 0 (one per bond), got "
                         f"shape {labels.shape}, dtype {labels.dtype}")
    used = np.unique(labels)
    labels = np.searchsorted(used, labels)
    return labels.astype(np.int64), tuple(f"class {int(k)}" for k in used)


# ------------------------------------------------------------------ the family
def _freeze(value):
    a = np.asarray(value, dtype=float)
    return (a.shape, tuple(a.reshape(-1).tolist()))


def _thaw(frozen):
    shape, values = frozen
    return np.asarray(values, dtype=float).reshape(shape)


@dataclasses.dataclass(frozen=True)
class SpinCouplings:
    """The family ``params -> SpinLattice`` of a coupling fit (module docstring): ``lattice``,
    ``labels`` (B,) bond class per bond (a tuple), ``fixed`` the held terms, ``axis`` n and
    ``spin_length`` s. Hashable (a static part of the compiled fit).

    >>> import jax.numpy as jnp, jaxsplit
    >>> from jaxsplit.explore._fit_spins import SpinCouplings
    >>> family = SpinCouplings.build(jaxsplit.lattices.lattice("square", 4), fixed={"field": (0.0, 0.0, 0.1)})
    >>> system = family({"exchange": jnp.array([1.0, 0.5])})
    >>> float(system.hamiltonian(system.uniform()))         # 16 x-bonds of J = 1, 16 y-bonds of 0.5, field
    -25.6
    """

    lattice: Lattice
    labels: tuple
    names: tuple
    fixed: tuple  # ((term, frozen value), ...)
    axis: tuple
    spin_length: float

    @classmethod
    def build(cls, lattice, classes="direction", fixed=None, axis=(0.0, 0.0, 1.0), spin_length: float = 1.0):
        labels, names = bond_classes(lattice, classes)
        fixed = dict(fixed or {})
        bad = sorted(set(fixed) - set(TERMS))
        if bad:
            raise InputError(f"unknown coupling {bad[0]!r}; the terms are {', '.join(TERMS)}")
        held = tuple(sorted((k, _freeze(_shaped(k, v, len(names), "fixed"))) for k, v in fixed.items()
                            if v is not None))
        axis = np.asarray(axis, dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.linalg.norm(axis) > 0:
            raise InputError(f"axis must be a nonzero finite 3-vector, got {axis.tolist()}")
        spin_length = positive(spin_length, "spin_length")
        return cls(lattice, tuple(labels.tolist()), names, held, tuple(axis.tolist()), spin_length)

    @property
    def n_classes(self) -> int:
        return len(self.names)

    def __call__(self, params):
        values = {k: _thaw(v) for k, v in self.fixed}
        values.update(params)
        labels = np.asarray(self.labels)

        def per_bond(name, default):  # (C,) or (C, 3) per class -> one per bond
            v = values.get(name)
            return default if v is None else jnp.asarray(v)[labels]

        field = values.get("field", (0.0, 0.0, 0.0))
        if jnp.ndim(field) == 0:  # a number: the field along the axis n
            field = field * jnp.asarray(self.axis) / np.linalg.norm(self.axis)
        return SpinLattice(self.lattice, exchange=per_bond("exchange", 0.0), anisotropic=per_bond("anisotropic", 0.0),
                           dm=per_bond("dm", None), anisotropy=values.get("anisotropy", 0.0), axis=self.axis,
                           field=field, spin_length=self.spin_length)


def _shaped(name, value, n_classes, what):
    """A term's value as its fitted shape: (C,) per class (a scalar shared), (C, 3) for DM
    (one vector shared), () for K, (3,) for B (or () for a field along the axis); finite."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} {name} must be numbers, got {value!r}") from None
    shape = {"exchange": (n_classes,), "anisotropic": (n_classes,), "dm": (n_classes, 3), "anisotropy": (),
             "field": a.shape if name == "field" and a.shape == () else (3,)}[name]
    if name in PER_CLASS and a.shape in ((), (3,)) and a.shape == shape[1:]:
        a = np.broadcast_to(a, shape)
    if a.shape != shape:
        raise InputError(f"{what} {name} must have shape {shape} ({n_classes} bond class"
                         f"{'es' if n_classes != 1 else ''}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what} {name} must be finite, got {a.tolist()}")
    return np.array(a)


def flipped(couplings: dict) -> dict:
    """The couplings of the flipped gauge (module docstring): J, Δ, D, K negated, B kept.

    >>> from jaxsplit.explore._fit_spins import flipped
    >>> flipped({"exchange": [1.0], "field": [0.0, 0.0, 0.1]})
    {'exchange': [-1.0], 'field': [0.0, 0.0, 0.1]}
    """
    return {k: (v if k == "field" else (-np.asarray(v)).tolist() if isinstance(v, (list, tuple)) else -v)
            for k, v in couplings.items()}


# ------------------------------------------------------------------ S(q, ω) as a measurement
def _broadening(omega, resolution: float) -> np.ndarray:
    """(n_ω, n_ω) Gaussian smoothing in ω of width ``resolution`` (rows sum to 1); identity at 0."""
    if resolution == 0:
        return np.eye(len(omega))
    k = np.exp(-0.5 * ((omega[:, None] - omega[None, :]) / resolution) ** 2)
    return k / k.sum(axis=1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class SpectrumMeasure:
    """``states (T, N, 3) -> S(q, ω)`` broadened by ``resolution`` and divided by ``scale``: the
    ``measure`` of a structure-factor fit (hashable: a static part of the compiled fit)."""

    lattice: Lattice
    dt: float
    components: str
    window: str
    resolution: float
    scale: float

    def kernel(self, n_frames: int):
        omega = np.fft.fftshift(np.fft.fftfreq(n_frames, d=self.dt)) * 2 * np.pi
        return _broadening(omega, self.resolution)

    def of_intensity(self, intensity):
        s = jnp.asarray(intensity)
        return (s @ jnp.asarray(self.kernel(s.shape[-1]).T, s.dtype)) / self.scale

    def __call__(self, states):
        sqw = structure_factor(states, self.lattice, self.dt, components=self.components, window=self.window)
        return self.of_intensity(sqw.intensity)


# ------------------------------------------------------------------ the fit
class CouplingFit(NamedTuple):
    """Outcome of ``fit_couplings``: ``couplings`` (term -> NumPy value: per class (C,) / (C, 3),
    K (), B (3,)), ``couplings_std`` (Gauss–Newton), ``fixed`` (the held terms), ``classes``
    (the bond class names), ``gauge`` (the exact symmetries stated, one line each),
    ``undetermined`` and ``weak`` (combinations {parameter: coefficient} with the eigenvalue
    ratio), ``loss``, ``noise_sigma``, ``iterations``, ``seconds``, ``target``, ``adjoint``,
    ``x0``; ``as_dict()`` for JSON.

    >>> import jaxsplit
    >>> jaxsplit.CouplingFit._fields[:4]
    ('couplings', 'couplings_std', 'fixed', 'classes')
    """

    couplings: dict
    couplings_std: dict
    fixed: dict
    classes: tuple
    gauge: tuple
    undetermined: tuple
    weak: tuple
    loss: float
    noise_sigma: float
    hessian_eigenvalues: np.ndarray
    iterations: int
    seconds: float
    target: str
    adjoint: str
    x0: np.ndarray  # the model's initial state (N, 3): given, the first observation, or fitted

    def as_dict(self) -> dict:
        def plain(v):
            if isinstance(v, dict):
                return {k: plain(x) for k, x in v.items()}
            if isinstance(v, (tuple, list)):
                return [plain(x) for x in v]
            if isinstance(v, (np.ndarray, np.generic)):
                return v.tolist()
            return v

        return {k: plain(v) for k, v in self._asdict().items()}


def _labels(params, names) -> list:
    """The flattened parameter names, in ``ravel_pytree`` order (sorted keys)."""
    out = []
    for key in sorted(params):
        shape = np.shape(params[key])
        for index in np.ndindex(shape):
            vector = key == "dm" or (key == "field" and len(shape) == 1)
            parts = [names[index[0]] if key in PER_CLASS else None, "xyz"[index[-1]] if vector else None]
            out.append(key + "".join(f"[{p}]" for p in parts if p is not None))
    return out


def _combinations(evals, evecs, labels, low: float, high: float) -> tuple:
    top = max(float(evals[-1]), 1e-300)
    out = []
    for k, value in enumerate(evals):
        ratio = float(value) / top
        if low <= ratio < high:
            v = evecs[:, k] / np.max(np.abs(evecs[:, k]))
            out.append({"eigenvalue_ratio": ratio,
                        "combination": {labels[i]: round(float(v[i]), 6) for i in np.argsort(-np.abs(v))
                                        if abs(v[i]) > 0.05}})
    return tuple(out)


def _times(t):
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"t must be numeric times, got {t!r}") from None
    if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputError(f"t must be finite, strictly increasing times, shape (n,) with n >= 2, got shape {t.shape}")
    return t


def fit_couplings(lattice, t, observed, start: dict, *, fixed=None, classes="direction", axis=(0.0, 0.0, 1.0),
                  spin_length: float = 1.0, target: str = "trajectory", x0=None, fit_x0: bool = False,
                  components: str = "xyz", window: str = "hann", resolution: float | None = None, scheme="strang", max_step: float = 0.05,
                  adjoint: str = "reversible", adam_steps: int = 0, adam_lr: float = 1e-3, lbfgs_iter: int = 100,
                  tol: float = 1e-10) -> CouplingFit:
    """Fit a spin lattice's couplings (module docstring) to ``observed`` at times ``t`` (n,).

    ``start``: the fitted terms and their starting values (``exchange`` per bond class or one
    shared number, ``anisotropic``, ``dm``, ``anisotropy``, ``field``); ``fixed``: held terms.
    ``target="trajectory"``: ``observed`` (n, N, 3) or (n, *lattice.shape, 3) spins;
    ``target="structure-factor"``: ``observed`` the S(q, ω) intensity (*size, n) of the data
    (``jaxsplit.structure_factor(states, lattice, dt, components=..., window=...).intensity``
    at the same equally spaced times) and ``x0`` the initial state. ``resolution``: the
    Gaussian broadening in ω (default 4 Δω, Δω = 2π/(n dt)). Returns a ``CouplingFit``.

    >>> import numpy as np, jax.numpy as jnp, jaxsplit
    >>> chain = jaxsplit.lattices.lattice("chain", 6)
    >>> truth = jaxsplit.spin_lattice(chain, exchange=1.0, field=(0.0, 0.0, 0.3))
    >>> x0 = truth.random_state(seed=1)
    >>> t = np.linspace(0.0, 2.0, 11)
    >>> obs = jaxsplit.integrate(jaxsplit.splitting(truth, "strang", "bonds"), x0, 0.02, 100, save_every=10).x
    >>> f = jaxsplit.fit_couplings(chain, t, obs, {"exchange": 0.9, "field": 0.2}, max_step=0.02)  # B along z
    >>> np.round(f.couplings["exchange"], 4).tolist(), np.round(f.couplings["field"], 4).tolist()
    ([1.0], 0.3)
    """
    begin = time.perf_counter()
    if target not in TARGETS:
        raise InputError(f"target must be one of {TARGETS}, got {target!r}")
    if not isinstance(start, dict) or not start:
        raise InputError(f"start must be a dict of the fitted terms and their starting values ({', '.join(TERMS)})")
    fixed = dict(fixed or {})
    both = sorted(set(start) & set(fixed))
    if both:
        raise InputError(f"{both[0]} is both fitted (start) and fixed; give it once")
    family = SpinCouplings.build(lattice, classes, fixed, axis, spin_length)
    bad = sorted(set(start) - set(TERMS))
    if bad:
        raise InputError(f"unknown coupling {bad[0]!r}; the terms are {', '.join(TERMS)}")
    dtype = jnp.result_type(float)
    params0 = {k: jnp.asarray(_shaped(k, v, family.n_classes, "start"), dtype) for k, v in start.items()}
    t = _times(t)
    lat = family.lattice
    gauge = ["units: couplings are angular frequencies in the inverse unit of t (hbar = 1); the time axis "
             "fixes their scale"]
    if target == "trajectory":
        obs = np.asarray(observed, dtype=float)
        if obs.shape[0] != len(t) or obs.size != len(t) * lat.n_sites * 3:
            raise InputError(f"observed spins must have shape ({len(t)}, {lat.n_sites}, 3) or ({len(t)}, "
                             f"*{lat.shape}, 3), got {obs.shape}")
        obs = obs.reshape(len(t), lat.n_sites, 3)
        if x0 is None:
            first = obs[0]
            x0 = spin_length * first / np.linalg.norm(first, axis=-1, keepdims=True)
        gauge.append("sign: fixed by the observed spins (a trajectory sees S itself)")
        kwargs = {"observe": None}
    else:
        if x0 is None:
            raise InputError("a structure-factor fit needs x0, the initial state the data were taken from")
        dt = np.diff(t)
        if not np.allclose(dt, dt[0], rtol=1e-9, atol=0):
            raise InputError("a structure-factor fit needs equally spaced times (S(q, ω) is a Fourier transform)")
        dt = float(dt[0])
        intensity = np.asarray(observed, dtype=float)
        want = tuple(lat.size) + (len(t),)
        if intensity.shape != want:
            raise InputError(f"observed S(q, ω) must have shape {want} (the lattice's q grid x {len(t)} frequencies), "
                             f"got {intensity.shape}")
        if not np.all(np.isfinite(intensity)):
            raise InputError("observed S(q, ω) must be finite")
        resolution = 4 * 2 * np.pi / (len(t) * dt) if resolution is None else positive(resolution, "resolution",
                                                                                           zero=True)
        scale = float(np.max(np.abs(intensity))) or 1.0
        measure = SpectrumMeasure(lat, dt, components, window, float(resolution), scale)
        observed = np.asarray(measure.of_intensity(jnp.asarray(intensity)))
        gauge.append("sign: S(q, w) is unchanged by S_i -> -S_i with (J, Delta, D, K) -> -(J, Delta, D, K), B kept; "
                     "fixed here by the given x0")
        kwargs = {"measure": measure}
    x0 = jnp.asarray(np.asarray(x0, dtype=float).reshape(lat.n_sites, 3), dtype)
    res = fit(family, t, observed if target != "trajectory" else jnp.asarray(obs, dtype), params0, x0=x0,
              fit_x0=bool(fit_x0), scheme=scheme, split="bonds", max_step=max_step, adjoint=adjoint, adam_steps=adam_steps,
              adam_lr=adam_lr, lbfgs_iter=lbfgs_iter, tol=tol, **kwargs)
    labels = _labels(params0, family.names)
    evals, evecs = res.hessian_eigenvalues, res.null_directions
    return CouplingFit(
        couplings={k: np.asarray(v) for k, v in res.params.items()},
        couplings_std={k: np.asarray(v) for k, v in res.params_std.items()},
        fixed={k: _thaw(v) for k, v in family.fixed}, classes=family.names, gauge=tuple(gauge),
        undetermined=_combinations(evals, evecs, labels, -math.inf, NULL_RATIO),
        weak=_combinations(evals, evecs, labels, NULL_RATIO, WEAK_RATIO),
        loss=res.loss, noise_sigma=res.noise_sigma, hessian_eigenvalues=evals, iterations=res.iterations,
        seconds=time.perf_counter() - begin, target=target, adjoint=adjoint, x0=np.asarray(res.x0))


def _all_params(family, couplings):
    return {k: jnp.asarray(_shaped(k, v, family.n_classes, "couplings"), jnp.result_type(float))
            for k, v in couplings.items() if v is not None}


def trajectory(lattice, couplings: dict, x0, t, *, classes="direction", axis=(0.0, 0.0, 1.0), spin_length=1.0,
               scheme="strang", max_step: float = 0.05):
    """States (n, N, 3) of the spin lattice with ``couplings`` (the terms of ``fit_couplings``'
    ``start``) from ``x0`` at times ``t`` (synthetic data; the couplings are traced, so other
    values of the same terms reuse the compiled run).

    >>> import numpy as np, jaxsplit
    >>> from jaxsplit.explore._fit_spins import trajectory
    >>> chain = jaxsplit.lattices.lattice("chain", 8)
    >>> trajectory(chain, {"exchange": 1.0}, jaxsplit.spin_lattice(chain).random_state(), np.arange(4) * 0.5).shape
    (4, 8, 3)
    """
    from ._fit import simulate

    family = SpinCouplings.build(lattice, classes, None, axis, spin_length)
    x0 = jnp.asarray(np.asarray(x0, dtype=float).reshape(family.lattice.n_sites, 3), jnp.result_type(float))
    return simulate(family, _all_params(family, couplings), x0, _times(t), scheme=scheme, split="bonds",
                    max_step=max_step)


def spectrum(lattice, couplings: dict, x0, t, *, components: str = "xyz", window: str = "hann", **kwargs):
    """S(q, ω) intensity (*size, n) of the couplings' trajectory from ``x0`` at the equally spaced
    times ``t`` (synthetic data for ``fit_couplings(..., target="structure-factor")``; ``kwargs``
    as for ``trajectory``).

    >>> import numpy as np, jaxsplit
    >>> from jaxsplit.explore._fit_spins import spectrum
    >>> chain = jaxsplit.lattices.lattice("chain", 8)
    >>> x0 = jaxsplit.spin_lattice(chain).perturbed(jaxsplit.spin_lattice(chain).uniform(), 0.1, seed=0)
    >>> spectrum(chain, {"exchange": 1.0}, x0, np.arange(32) * 0.5).shape
    (8, 32)
    """
    t = _times(t)
    states = trajectory(lattice, couplings, x0, t, **kwargs)
    return np.asarray(structure_factor(states, lattice, float(t[1] - t[0]), components=components,
                                       window=window).intensity)


def identifiability(lattice, couplings: dict, x0, t, fitted=None, *, classes="direction", axis=(0.0, 0.0, 1.0),
                    spin_length: float = 1.0, scheme="strang", max_step: float = 0.05) -> dict:
    """What a trajectory from ``x0`` at times ``t`` would determine, before any data: the
    Gauss–Newton Hessian JᵀJ of the spins in the ``fitted`` terms (default: every term of
    ``couplings``) at ``couplings``; {"eigenvalues", "labels", "undetermined", "weak"} as in
    ``CouplingFit``.

    >>> import jaxsplit
    >>> from jaxsplit.explore._fit_spins import identifiability
    >>> chain = jaxsplit.lattices.lattice("chain", 6)
    >>> up = jaxsplit.spin_lattice(chain).uniform()                     # collinear: nothing moves
    >>> r = identifiability(chain, {"exchange": 1.0}, up, [0.0, 0.5, 1.0])
    >>> r["undetermined"][0]["combination"]
    {'exchange[(1)]': 1.0}
    """
    from ._fit import Model, _curvature

    fitted = list(couplings) if fitted is None else list(fitted)
    held = {k: v for k, v in couplings.items() if k not in fitted}
    family = SpinCouplings.build(lattice, classes, held, axis, spin_length)
    params = _all_params(family, {k: couplings[k] for k in fitted})
    t = _times(t)
    x0 = jnp.asarray(np.asarray(x0, dtype=float).reshape(family.lattice.n_sites, 3), jnp.result_type(float))
    from ._fit import substeps
    from ..core._schemes import schemes

    model = Model(family, schemes.resolve(scheme), "bonds", (), substeps(t, max_step), False, None)
    data = {"x0": x0, "dts": jnp.asarray(np.diff(t)), "fixed": None,
            "observed": jnp.zeros((len(t), family.lattice.n_sites * 3))}
    states = np.asarray(simulate_clean(model, params, data))
    data["observed"] = jnp.asarray(states.reshape(len(t), -1))
    jac, _ = _curvature(model, {"params": params, "x0": None}, data)
    jac = np.asarray(jac)
    evals, evecs = np.linalg.eigh(jac.T @ jac)
    labels = _labels(params, family.names)
    return {"eigenvalues": evals, "labels": labels,
            "undetermined": _combinations(evals, evecs, labels, -math.inf, NULL_RATIO),
            "weak": _combinations(evals, evecs, labels, NULL_RATIO, WEAK_RATIO)}


def simulate_clean(model, params, data):
    """The model's predicted spins (n, N, 3) at ``params`` (residuals against zeros)."""
    theta = {"params": params, "x0": None}
    return _residuals_jit(model, theta, data).reshape(len(data["dts"]) + 1, -1, 3)


@jax.jit
def _residuals_jit(model, theta, data):
    return model.residuals(theta, data)
