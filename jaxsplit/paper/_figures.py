"""The audit's figures: at most one per claim, rendered in memory to PNG bytes (matplotlib,
imported lazily, Agg). ``render`` maps {claim id: data the claim measured} to
{claim id: (file name, caption, PNG bytes)}; ``_output`` writes them.
"""

import io
import math

import numpy as np

from ._records import ROUND_OFF
from ._report import number

DPI = 110
GUIDE_OFFSET = 0.2  # the claimed-order guide is drawn this factor below the measured ladder


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _minor_label(v, _) -> str:
    """Minor ticks of a short log axis: label 2·10^k and 5·10^k only (all of them overprint)."""
    mantissa = v / 10 ** math.floor(math.log10(v) + 1e-9)
    return f"{v:g}" if round(mantissa) in (2, 5) and abs(mantissa - round(mantissa)) < 1e-6 else ""


def _png(fig) -> bytes:
    plt = _plt()
    for ax in fig.axes:
        if ax.get_xscale() == "log":
            lo, hi = ax.get_xlim()
            short = math.log10(hi / lo) < 1.5  # fewer than two labelled decades
            ax.xaxis.set_minor_formatter(plt.FuncFormatter(_minor_label) if short else plt.NullFormatter())
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, bbox_inches="tight")  # "tight": legends outside the axes
    plt.close(fig)
    return buffer.getvalue()


def _thm41(curves):
    fig, ax = _plt().subplots(figsize=(6, 4))
    for label, (hs, ds) in curves.items():
        ax.loglog(hs, np.maximum(ds, 1e-17), "o-", ms=3, label=label)
    ax.axhline(ROUND_OFF, color="k", lw=0.6, ls=":")
    ax.set_xlabel("h")
    ax.set_ylabel("max Poisson defect")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return fig


def _orders(ladders):
    fig, ax = _plt().subplots(figsize=(5.5, 4))
    for name, row in ladders.items():
        hs, errs = np.asarray(row["step_sizes"]), np.asarray(row["errors"])
        line = ax.loglog(hs, errs, "o-", ms=3, label=f"{name}: fitted p = {row['measured']:.2f}")[0]
        used = np.asarray(row["used"])
        anchor = np.flatnonzero(used)[-1] if used.any() else len(hs) - 1
        guide = GUIDE_OFFSET * errs[anchor] * (hs / hs[anchor]) ** row["claimed"]  # below the data, parallel
        ax.loglog(hs, guide, "--", lw=0.8, color=line.get_color(), label=f"slope {row['claimed']} (claimed)")
    ax.set_xlabel("h")
    ax.set_ylabel("global error at T = 10")
    ax.legend(fontsize=7)
    return fig


def _rem42(data):
    runs, fits, t_end = data["runs"], data["fits"], data["t_end"]
    fig, axes = _plt().subplots(1, 2, figsize=(11, 4))
    for ax, key in zip(axes, ("energy", "casimir")):
        for name, run in runs.items():
            label = f"{name} (h = {run['h']:g})"
            ax.loglog(run["t"][1:], np.maximum(run[key][1:], 1e-17), lw=0.8, label=label)
        c, p, amplitude, when = fits[key]
        t_far = max(t_end, 2 * when) if when is not None else t_end
        ts = np.geomspace(runs["rk4"]["t"][1], t_far, 50)
        ax.loglog(ts, c * ts**p, "--", color="C2", lw=1, label=f"rk4 fit c·t^{p:.2f} (t ≥ {0.1 * t_end:g})")
        ax.axhline(amplitude, color="C0", ls=":", lw=1, label="lie-trotter: max over the run")
        if when is not None:
            ax.plot([when], [amplitude], "kx", ms=8, label=f"rk4 exceeds it from t = {number(when, 3)}")
        ax.axvline(t_end, color="0.6", lw=0.6)
        ax.set_xlabel("t (grey line: end of the runs)")
        ax.set_ylabel(f"relative {key} error")
        ax.legend(fontsize=7, loc="lower right" if key == "energy" else "center right")
    return fig


def _rem44(curves):
    fig, axes = _plt().subplots(2, 3, figsize=(12, 6.5), sharex=True, sharey="row")
    bodies = sorted({row["s"] for row in curves.values()})
    for row in curves.values():
        top, bottom = axes[0, row["axis"]], axes[1, row["axis"]]
        color = f"C{bodies.index(row['s'])}"
        tau = np.asarray(row["half_trace"])
        top.plot(row["h"], tau, lw=1, color=color, label=f"I = (2, {row['s']:g}, 1)")
        radius = np.abs(tau) + np.sqrt(np.maximum(tau**2 - 1, 0))  # spectral radius of a det-1 2×2 block
        bottom.loglog(row["h"], np.where(radius - 1 > 0, radius - 1, np.nan), lw=1, color=color)
        if row["h_star"] is not None:
            side = np.sign(np.interp(row["h_star"], row["h"], tau))  # leaves through +1 or −1
            top.plot([row["h_star"]], [side], "o", color=color, ms=6, mfc="none")
    for axis in range(3):
        top, bottom = axes[0, axis], axes[1, axis]
        top.set_xscale("log")
        top.set_yscale("symlog", linthresh=1, linscale=1.5)
        top.axhspan(-1, 1, color="0.9", zorder=0)
        top.set_title(f"equilibrium m = e{axis + 1}", fontsize=9)
        bottom.set_xlabel("h")
    axes[0, 0].set_ylabel("tr(DΦ)/2 on the tangent plane\n(grey band: roots on the unit circle)", fontsize=9)
    axes[1, 0].set_ylabel("max |λ| − 1\n(no line: roots on the unit circle)", fontsize=9)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=4, fontsize=8, bbox_to_anchor=(0.5, 0.0))
    return fig


def _subscript(n) -> str:
    return str(n).translate(str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉"))


def _rem45(data):
    pts, axis, alpha = data["orbit"], data["axis"], data["alpha"]
    u = np.array([1.0, 0.0, 0.0]) - axis[0] * axis
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    x, y = pts @ u, pts @ w
    fig, (left, right) = _plt().subplots(1, 2, figsize=(10, 4.5), gridspec_kw={"width_ratios": [1, 1.2]})
    left.plot(x, y, ".", ms=1, color="0.6", label=f"Π₁ … Π{_subscript(len(pts))}")
    p0 = np.array([1.0, 0.0, 0.0])
    left.plot([p0 @ u], [p0 @ w], "k*", ms=10, label="Π₀ = (1, 0, 0)")
    left.plot(x[:10], y[:10], "o", ms=4, color="C3", label="Π₁ … Π₁₀: R turns Π by α each step")
    left.set_aspect("equal")
    left.set_xlabel("Π·u  (u ⊥ rotation axis a)")
    left.set_ylabel("Π·(a × u)")
    left.set_title(f"orbit on the circle Π·a = {p0 @ axis:.3f}, α = {alpha:.4f} rad", fontsize=9)
    left.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14))
    counts, gaps = np.asarray(data["counts"]), np.asarray(data["gaps"])
    right.loglog(counts, gaps, "o-", ms=3, label="largest unvisited arc after n iterates")
    right.loglog(counts, 2 * np.pi / counts, "--", lw=0.8, label="2π/n (evenly spread points)")
    right.set_xlabel("n")
    right.set_ylabel("arc (rad)")
    right.legend(fontsize=7)
    return fig


_LADDER = "Global error at T = 10 against h (symmetric body, exact reference); dashed: the claimed slope"
_POISSON = ("Poisson defect max|DΦ Π DΦᵀ − Π∘Φ| against h: (4.3) as printed and Lie–Trotter on the symmetric "
            "body, classical methods on the asymmetric standard body; dotted: round-off threshold")
_INVARIANTS = ("Relative energy and Casimir errors at equal cost (40 units per unit time) up to T = 1000; "
               "dashed: RK4's fitted power law, extrapolated to where it meets Lie–Trotter's maximum "
               "(dotted)")
_EQUILIBRIA = ("Half-trace of Lie–Trotter's DΦ at the relative equilibria against h: inside the grey band "
               "the roots are on the unit circle, outside they are a real pair with product 1; circles: "
               "first departures")
_ORBIT = "The orbit Π_n = Rⁿ Π_0 in the plane of its circle, and how evenly it covers the circle"

# claim id -> (plotter, file name, caption)
_PLOTS = {
    "thm4.1": (_thm41, "thm41_poisson_defects.png", _POISSON),
    "order2": (_orders, "order2_ladder.png", _LADDER),
    "order4": (_orders, "order4_ladder.png", _LADDER),
    "order2n+2": (_orders, "order2n2_ladder.png", _LADDER),
    "rem4.2": (_rem42, "rem42_invariants.png", _INVARIANTS),
    "rem4.4": (_rem44, "rem44_equilibria.png", _EQUILIBRIA),
    "rem4.5": (_rem45, "rem45_orbit.png", _ORBIT),
}


def figure_name(cid: str) -> str | None:
    """The file name of a claim's figure (``None`` when it draws none)."""
    return _PLOTS[cid][1] if cid in _PLOTS else None


def figure_caption(cid: str) -> str | None:
    """The caption of a claim's figure (``None`` when it draws none)."""
    return _PLOTS[cid][2] if cid in _PLOTS else None


def render(figures: dict) -> dict:
    """{claim id: data} -> {claim id: (file name, caption, PNG bytes)}."""
    out = {}
    for cid, data in figures.items():
        plot, name, caption = _PLOTS[cid]
        out[cid] = (name, caption, _png(plot(data)))
    return out
