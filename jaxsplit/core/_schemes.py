"""Composition schemes as data, and the registry of named schemes.

Three forms cover every scheme, and each reduces to one list of Lie–adjoint weights or to
an alternating two-piece sequence (see ``_compose.word``):

* ``symmetric`` — Ψ_h = S_{γ_s h} ∘ … ∘ S_{γ_1 h}, S the Strang step (γ palindromic);
* ``lie-adjoint`` — Ψ_h = Φ_{α_2m h} ∘ Φ*_{α_2m−1 h} ∘ … ∘ Φ_{α_2 h} ∘ Φ*_{α_1 h}, with
  Φ_h = φⁿ_h ∘ … ∘ φ¹_h the Lie–Trotter step (4.1) and Φ* its adjoint (adjoint first);
* ``partitioned`` — e^{a_1 hA} e^{b_1 hB} … e^{b_s hB} e^{a_{s+1} hA} for two pieces A, B,
  stored interleaved as (a_1, b_1, a_2, …, a_{s+1}); A acts first.

A symmetric scheme may carry a *processor* (Blanes–Casas–Murua's processed methods): Strang
weights π with P = S_{π_r h} ∘ … ∘ S_{π_1 h}, and the step is Ψ_h = P⁻¹ ∘ K_h ∘ P with K_h the
composition of γ (the kernel). The processor telescopes over a run (Ψ_h^n = P⁻¹ ∘ K_h^n ∘ P),
so n steps cost n kernels and one processor each way, and the kernel needs far fewer order
conditions than a plain composition of the same order (``Composition.advance``).

Coefficients are from ``shared/reference/coefficients.md`` (sources per table below); the
order of every scheme is measured in the test suite, not trusted.
"""

import dataclasses
import difflib
import math
import re
from collections.abc import Iterator, Mapping

from .._bounds import triple_jump_name, triple_jump_order
from ._errors import InputError

FORMS = ("symmetric", "lie-adjoint", "partitioned")
_EPS = 2.0**-52


def _mirror(half, centre=None):
    """Palindrome from the first half (and the centre, for odd lengths)."""
    half = tuple(float(c) for c in half)
    middle = () if centre is None else (float(centre),)
    return half + middle + half[::-1]


@dataclasses.dataclass(frozen=True)
class Scheme:
    """A composition scheme: frozen, hashable, validated when built.

    ``form`` is ``"symmetric"``, ``"lie-adjoint"`` or ``"partitioned"`` (module docstring);
    ``coefficients`` a tuple of Python floats (the weights γ, α, or a/b interleaved), summing
    to 1 (per piece for partitioned); ``order`` the claimed order (measured in the test
    suite). Pure data: static wherever it is used (a new scheme compiles anew; use ``roll``
    to make the weights traced arrays).

    >>> import jaxsplit
    >>> s = jaxsplit.Scheme("my-strang", 2, "symmetric", (1.0,), "Strang 1968")
    >>> s.stages, s.symmetric, jaxsplit.schemes["suzuki-5"].order
    (1, True, 4)
    >>> jaxsplit.Scheme("bad", 2, "symmetric", (0.5,))
    Traceback (most recent call last):
    ...
    jaxsplit.InputError: bad: weights must sum to 1 (consistency), got (0.5,)
    """

    name: str
    order: int
    form: str
    coefficients: tuple[float, ...]
    citation: str = ""
    processor: tuple[float, ...] = ()  # Strang weights of P (first acts first); () = none

    @property
    def processed(self) -> bool:
        return bool(self.processor)

    def __post_init__(self):
        if not re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", self.name or ""):
            raise InputError(f"scheme name must be lower-case kebab form, got {self.name!r}")
        if self.form not in FORMS:
            raise InputError(f"scheme form must be one of {FORMS}, got {self.form!r}")
        if not (isinstance(self.order, int) and self.order >= 1):
            raise InputError(f"scheme order must be a positive integer, got {self.order!r}")
        coefs = tuple(float(c) for c in self.coefficients)
        object.__setattr__(self, "coefficients", coefs)
        if not coefs or not all(math.isfinite(c) for c in coefs):
            raise InputError(f"{self.name}: coefficients must be finite numbers, got {coefs}")
        processor = tuple(float(c) for c in self.processor)
        object.__setattr__(self, "processor", processor)
        if processor and (self.form != "symmetric" or not all(math.isfinite(c) for c in processor)):
            raise InputError(f"{self.name}: a processor is finite Strang weights of a symmetric scheme, "
                             f"got {processor} for a {self.form} one")
        tol = 8 * _EPS * sum(abs(c) for c in coefs)
        if self.form == "lie-adjoint" and len(coefs) % 2:
            raise InputError(f"{self.name}: a lie-adjoint scheme needs an even number of weights")
        if self.form == "partitioned":
            if len(coefs) % 2 == 0 or len(coefs) < 3:
                raise InputError(f"{self.name}: partitioned weights (a1, b1, ..., a_s+1) are odd in number")
            sums = (math.fsum(coefs[0::2]), math.fsum(coefs[1::2]))
        else:
            sums = (math.fsum(coefs),)
        if any(abs(s - 1) > tol for s in sums):
            raise InputError(f"{self.name}: weights must sum to 1 (consistency), got {sums}")
        if self.form == "symmetric":
            if any(abs(a - b) > tol for a, b in zip(coefs, coefs[::-1])):
                raise InputError(f"{self.name}: symmetric-composition weights must be a palindrome")
            if self.order % 2:
                raise InputError(f"{self.name}: a symmetric composition has even order, got {self.order}")
            # Necessary conditions Σγ^(2k+1) = 0 for 2k+1 < order.
            for k in range(3, self.order, 2):
                residual = math.fsum(c**k for c in coefs)
                if abs(residual) > 64 * _EPS * sum(abs(c) ** k for c in coefs):
                    raise InputError(f"{self.name}: Σγ^{k} = {residual:.3g} is not 0 as order {self.order} requires")

    @property
    def stages(self) -> int:
        """Strang steps (symmetric; the kernel's, if processed), Lie/adjoint half-steps
        (lie-adjoint) or B-flows (partitioned)."""
        return len(self.coefficients) // 2 if self.form == "partitioned" else len(self.coefficients)

    @property
    def symmetric(self) -> bool:
        """Time-symmetric (Ψ_h⁻¹ = Ψ_{−h}): the composition word is a palindrome (a processed
        step P⁻¹ ∘ K_h ∘ P is not, in general: P depends on h)."""
        from ._compose import word

        if self.processed:
            return False
        w = word(self, n_pieces=2)
        return all(p == q and abs(a - b) <= 8 * _EPS for (p, a), (q, b) in zip(w, w[::-1]))

    def pieces_allowed(self, n_pieces: int) -> bool:
        return n_pieces == 2 if self.form == "partitioned" else n_pieces >= 1


def triple_jump(order: int) -> Scheme:
    """The paper's recursive triple jump of even order ``order`` = 2n+2 (3^n Strang steps);
    ``schemes["triple-jump-N"]`` resolves to it for any even N >= 2 up to 14 (3^6 = 729
    stages): beyond, the stages exceed ``MAX_STAGES`` and are refused before they are built.

    >>> import jaxsplit
    >>> s = jaxsplit.triple_jump(4)
    >>> s.name, s.stages, round(sum(s.coefficients), 15)
    ('triple-jump-4', 3, 1.0)
    """
    if not (isinstance(order, int) and order >= 2 and order % 2 == 0):
        raise InputError(f"triple-jump order must be an even integer >= 2, got {order!r}")
    triple_jump_order(order, f"triple_jump({order})")
    gammas = (1.0,)
    for p in range(2, order, 2):  # lift order p to p + 2
        x1 = 1.0 / (2.0 - 2.0 ** (1.0 / (p + 1)))
        x0 = -(2.0 ** (1.0 / (p + 1))) * x1
        gammas = tuple(x * g for x in (x1, x0, x1) for g in gammas)
    return Scheme(
        f"triple-jump-{order}", order, "symmetric", gammas,
        "Yoshida 1990 / Creutz–Gocksch 1989; seed paper §4 (recursive, 3^n stages)",
    )


def _bm_lie_adjoint(half):
    """Blanes–Moan publish ~15 digits: restore Σα = 1 by recomputing the central weight."""
    half = list(half)
    half[-1] = 0.5 - math.fsum(half[:-1])
    return _mirror(half)


def _bm_partitioned(a_half, b_half):
    """Interleave a (mirrored around its free centre) with b (mirrored); centres recomputed."""
    a = list(a_half) + [1.0 - 2.0 * math.fsum(a_half)] + list(a_half[::-1])
    b_centre = 0.5 - math.fsum(b_half)
    b = list(b_half) + [b_centre, b_centre] + list(b_half[::-1])
    out = []
    for ai, bi in zip(a, b + [None]):
        out += [ai] if bi is None else [ai, bi]
    return tuple(out)


def _bcm_processed(kernel_half, processor_tail):
    """Blanes–Casas–Murua publish 15 digits and the free weights only: the kernel's centre
    restores Σγ = 1, the processor's first weight makes its first half sum to 0, and its second
    half is the first negated (π_{r/2+k} = −π_k)."""
    first = [-math.fsum(processor_tail)] + list(processor_tail)
    half = [-g for g in first]  # the source lists −π
    return (_mirror(kernel_half, 1.0 - 2.0 * math.fsum(kernel_half)), tuple(half + [-g for g in half]))


_BCM8_KERNEL, _BCM8_PROCESSOR = _bcm_processed(
    [0.168, 0.168, 0.585550530805562, -0.460090457516872, 0.172863148729731, 0.179664539695039],
    [-0.008488123494574411, -0.337188967354338, 0.333987768164597, 0.588351189003849, 0.162324207599241,
     -0.511744926116413, 0.236885952363384, 0.598212975943381, -0.543415765371656])

_SQ19 = math.sqrt(19.0)

_TABLES = (
    Scheme("lie-trotter", 1, "lie-adjoint", (0.0, 1.0),
           "Trotter 1959; seed paper (4.1): φ¹ first, then φ², φ³"),
    Scheme("lie-trotter-adjoint", 1, "lie-adjoint", (1.0, 0.0),
           "adjoint of (4.1): φ³ first, then φ², φ¹"),
    Scheme("strang", 2, "symmetric", (1.0,), "Strang 1968; seed paper §4 (φ²_t)"),
    Scheme("suzuki-5", 4, "symmetric",
           _mirror([1 / (4 - 4 ** (1 / 3))] * 2, -(4 ** (1 / 3)) / (4 - 4 ** (1 / 3))),
           "Suzuki 1990 fractal, closed form"),
    Scheme("mclachlan-ss5", 4, "symmetric",
           _mirror([0.28, 0.6254664284676700450], -0.8109328569353400900),
           "McLachlan 1995 SS5 (via Principia)"),
    Scheme("yoshida-6a", 6, "symmetric",
           _mirror([0.78451361047755726381949763, 0.23557321335935813368479318,
                    -1.17767998417887100694641568], 1.31518632068391121888424973),
           "Yoshida 1990 solution A (via GeometricIntegrators.jl, Principia)"),
    Scheme("mclachlan-ss9", 6, "symmetric",
           _mirror([0.1867, 0.55549702371247839916, 0.12946694891347535806,
                    -0.84326562338773460855], 0.9432033015235617027),
           "McLachlan 1995 SS9 (via Principia)"),
    Scheme("kahan-li-6", 6, "symmetric",
           _mirror([0.39216144400731413927925056, 0.33259913678935943859974864,
                    -0.70624617255763935980996482, 0.08221359629355080023149045],
                   0.79854399093482996339895035),
           "Kahan–Li 1997 s9odr6a (via OrdinaryDiffEq.jl KahanLi6)"),
    Scheme("mclachlan-ss15", 8, "symmetric",
           _mirror([0.74167036435061295344822780, -0.40910082580003159399730010,
                    0.19075471029623837995387626, -0.57386247111608226665638773,
                    0.29906418130365592384446354, 0.33462491824529818378495798,
                    0.31529309239676659663205666], -0.79688793935291635401978884),
           "McLachlan 1995 SS15 (via OrdinaryDiffEq.jl McAte8, Principia)"),
    Scheme("mclachlan-ss17", 8, "symmetric",
           _mirror([0.12886597938144329897, 0.5815140871052509624, -0.41017537146985013753,
                    0.1851469357165877327, -0.40955234342085141934, 0.14440594108001204106,
                    0.27833550039367965131, 0.31495668391629485789], -0.626994825405133975),
           "McLachlan 1995 SS17 (via Principia)"),
    Scheme("kahan-li-8", 8, "symmetric",
           _mirror([0.13020248308889008087881763, 0.56116298177510838456196441,
                    -0.38947496264484728640807860, 0.15884190655515560089621075,
                    -0.39590389413323757733623154, 0.18453964097831570709183254,
                    0.25837438768632204729397911, 0.29501172360931029887096624],
                   -0.60550853383003451169892108),
           "Kahan–Li 1997 s17odr8a (via OrdinaryDiffEq.jl KahanLi8)"),
    Scheme("kahan-li-10", 10, "symmetric",
           _mirror([0.09040619368607278492161150, 0.53591815953030120213784983,
                    0.35123257547493978187517736, -0.31116802097815835426086544,
                    -0.52556314194263510431065549, 0.14447909410225247647345695,
                    0.02983588609748235818064083, 0.17786179923739805133592238,
                    0.09826906939341637652532377, 0.46179986210411860873242126,
                    -0.33377845599881851314531820, 0.07095684836524793621031152,
                    0.23666960070126868771909819, -0.49725977950660985445028388,
                    -0.30399616617237257346546356, 0.05246957188100069574521612],
                   0.44373380805019087955111365),
           "Kahan–Li 1997 order 10, 33 stages (via WaveBlocksND KL10)"),
    Scheme("sofroniou-spaletta-10", 10, "symmetric",
           _mirror([0.07879572252168641926390768, 0.31309610341510852776481247,
                    0.02791838323507806610952027, -0.22959284159390709415121340,
                    0.13096206107716486317465686, -0.26973340565451071434460973,
                    0.07497334315589143566613711, 0.11199342399981020488957508,
                    0.36613344954622675119314812, -0.39910563013603589787862981,
                    0.10308739852747107731580277, 0.41143087395589023782070412,
                    -0.00486636058313526176219566, -0.39203335370863990644808194,
                    0.05194250296244964703718290, 0.05066509075992449633587434,
                    0.04967437063972987905456880], 0.04931773575959453791768001),
           "Sofroniou–Spaletta 2005, 35 stages (via OrdinaryDiffEq.jl SofSpa10)"),
    Scheme("blanes-casas-murua-8", 8, "symmetric", _BCM8_KERNEL,
           "Blanes–Casas–Murua 2006, processed: 13-stage kernel, 20-stage processor, effective order 8 "
           "(via Blanes–Casas–Murua 2024, arXiv:2401.01722, Table 8.1); centres recomputed",
           _BCM8_PROCESSOR),
    Scheme("mclachlan-m4", 4, "lie-adjoint",
           _mirror([(14 - _SQ19) / 108, (146 + 5 * _SQ19) / 540, (-23 - 20 * _SQ19) / 270,
                    (-2 + 10 * _SQ19) / 135, 1 / 5]),
           "McLachlan 1995 (via pyhamsys, GeometricIntegrators.jl McLachlan4)"),
    Scheme("blanes-moan-s6", 4, "lie-adjoint",
           _bm_lie_adjoint([0.0792036964311957, 0.1303114101821663, 0.2228614958676077,
                            -0.3667132690474257, 0.3246481886897062, 0.1096884778767498]),
           "Blanes–Moan 2002 S6 (via pyhamsys BM4); centre weight recomputed for Σ = 1"),
    Scheme("blanes-moan-s10", 6, "lie-adjoint",
           _bm_lie_adjoint([0.050262764400392, 0.098553683500650, 0.314960616927694,
                            -0.447346482695478, 0.492426372489876, -0.425118767797691,
                            0.237063913978122, 0.195602488600053, 0.346358189850727,
                            -0.362762779254345]),
           "Blanes–Moan 2002 S10 (via pyhamsys BM6); centre weight recomputed for Σ = 1"),
    Scheme("blanes-moan-s6-prk", 4, "partitioned",
           _bm_partitioned([0.0792036964311957, 0.353172906049774, -0.0420650803577195],
                           [0.209515106613362, -0.143851773179818]),
           "Blanes–Moan 2002 S6, partitioned (via Principia); centres recomputed"),
    Scheme("blanes-moan-s10-prk", 6, "partitioned",
           _bm_partitioned([0.0502627644003922, 0.413514300428344, 0.0450798897943977,
                            -0.188054853819569, 0.541960678450780],
                           [0.148816447901042, -0.132385865767784, 0.067307604692185,
                            0.432666402578175]),
           "Blanes–Moan 2002 S10, partitioned (via Principia); centres recomputed"),
)

_TRIPLE_JUMP = re.compile(r"triple-jump-(\d+)")


class SchemeRegistry(Mapping):
    """The registry of named schemes (``jaxsplit.schemes``): a read-only mapping name -> ``Scheme``.

    ``triple-jump-N`` resolves for any even N from 2 to 14; an unknown name raises an ``InputError``
    with the closest names. ``register`` adds a scheme; ``resolve`` accepts a name or a
    ``Scheme``.

    >>> import jaxsplit
    >>> len(jaxsplit.schemes) >= 21, "strang" in jaxsplit.schemes, "triple-jump-12" in jaxsplit.schemes
    (True, True, True)
    >>> jaxsplit.schemes.resolve("kahan-li-6").order
    6
    """

    def __init__(self, schemes=()):
        self._schemes: dict[str, Scheme] = {}
        for s in schemes:
            self.register(s)

    def register(self, scheme: Scheme) -> Scheme:
        if not isinstance(scheme, Scheme):
            raise InputError(f"only Scheme objects can be registered, got {type(scheme).__name__}")
        self._schemes[scheme.name] = scheme
        return scheme

    def __getitem__(self, name: str) -> Scheme:
        if isinstance(name, str):
            if name in self._schemes:
                return self._schemes[name]
            match = _TRIPLE_JUMP.fullmatch(name)
            if match:
                triple_jump_name(name, f"scheme {name!r}")  # bounded before int() of its digits
                return triple_jump(int(match.group(1)))
        close = difflib.get_close_matches(str(name), list(self), n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise InputError(f"unknown scheme {name!r}{hint} (`jaxsplit schemes` lists them)")

    def __iter__(self) -> Iterator[str]:
        return iter(self._schemes)

    def __len__(self) -> int:
        return len(self._schemes)

    def __contains__(self, name) -> bool:
        try:
            self[name]
        except InputError:
            return False
        return True

    def resolve(self, scheme: "Scheme | str") -> Scheme:
        return scheme if isinstance(scheme, Scheme) else self[scheme]


schemes = SchemeRegistry(
    _TABLES[:3] + tuple(triple_jump(p) for p in (4, 6, 8)) + _TABLES[3:]
)
