"""Figures of the command line (matplotlib, Agg backend, imported only when drawing).

``simulate_figure``: one or two spheres on the left (orthographic views of the visible
hemisphere, seen along the orbits' area vector, with level curves where a function is given: m on |m| = const with the energy's
levels; the body axes in space for the attitude; Γ on the unit sphere with the potential's
levels), the errors against time on the right (log scales: the energy, the other
invariants, the distance to the exact solution). The orbit is drawn only between states
close together on the sphere (a chord between far-apart saved states would cut across it),
densely from partial steps when the saved states are sparse; the states at requested times
are marked. Error curves are thinned by keeping each bucket's maximum, and the "max" shown
is the summary's, over every saved state.

``sweep_figure``: the errors of a sweep against the step size, grouped by inertia ratios
(median and max over the states of each group).
"""

from typing import NamedTuple

import numpy as np

_FLOOR = 1e-17  # exact zeros (round-off luck) are drawn at this floor on the log scales
_MAX_POINTS = 20_000
CHORD = 0.08  # radians: consecutive points farther apart on the sphere are not joined


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


class Curve(NamedTuple):
    """A path on a sphere: ``points`` (n, 3) saved states, ``dense`` (k, 3) or None (partial
    steps drawn as the line), ``at`` (j, 3) or None (requested times, marked)."""

    points: np.ndarray
    label: str
    color: str
    dense: np.ndarray | None = None
    at: np.ndarray | None = None


class Sphere(NamedTuple):
    """One sphere panel: curves, radius, optional level function (points (..., 3) -> values),
    labels of the coordinate axes, fixed points to mark ((label, (3,)) pairs)."""

    title: str
    curves: list
    radius: float
    levels: object = None
    level_label: str = ""
    axis_names: tuple = ("e1", "e2", "e3")
    marks: tuple = ()


def area_vector(paths) -> np.ndarray:
    """½ Σ p_k × p_(k+1) over each path (closed by its chord), summed: a plane with unit normal
    n sees the paths enclose the area |A·n|, largest along A."""
    total = np.zeros(3)
    for p in paths:
        p = p[np.all(np.isfinite(p), axis=1)]
        if len(p) > 2:
            total += 0.5 * np.sum(np.cross(p, np.roll(p, -1, axis=0)), axis=0)
    return total


def _view_basis(points: np.ndarray, paths=()):
    """A view direction v and a screen basis: along the paths' area vector (the view in which
    the orbits enclose the largest area, so that none is seen edge-on as a line), turned to
    the side of their mean; paths that enclose no area (a point, a short arc) are seen along
    their mean point, tilted a little to an oblique direction."""
    mean = points.mean(axis=0) if len(points) else np.zeros(3)
    scale = max(1.0, np.max(np.abs(points)) if len(points) else 1.0)
    area = area_vector(paths)
    oblique = np.array([1.0, 0.8, 0.9]) / np.linalg.norm([1.0, 0.8, 0.9])
    norm = np.linalg.norm(mean)
    if np.linalg.norm(area) > 1e-6 * scale**2:
        v = area / np.linalg.norm(area)
        v = -v if v @ mean < 0 else v
    elif norm > 1e-12 * scale:
        direction = mean / norm
        tilt = oblique - (oblique @ direction) * direction  # tilt the view off the mean a little
        tilt_norm = np.linalg.norm(tilt)
        v = direction if tilt_norm < 1e-12 else 0.8 * direction + 0.6 * tilt / tilt_norm
    else:
        v = oblique
    v = v / np.linalg.norm(v)
    up = np.array([0.0, 0.0, 1.0])
    if abs(v @ up) > 0.95:
        up = np.array([0.0, 1.0, 0.0])
    e1 = np.cross(up, v)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(v, e1)
    return v, e1, e2


def _joined(p: np.ndarray, radius: float) -> np.ndarray:
    """``p`` with NaN rows inserted between consecutive points more than ``CHORD`` apart."""
    if len(p) < 2:
        return p
    gap = np.linalg.norm(np.diff(p, axis=0), axis=1) > CHORD * radius
    if not gap.any():
        return p
    out = np.insert(p, np.flatnonzero(gap) + 1, np.nan, axis=0)
    return out


def sparse(points: np.ndarray, radius: float) -> bool:
    """Whether consecutive points are too far apart on the sphere to be joined by a line."""
    return len(points) > 1 and bool(np.mean(np.linalg.norm(np.diff(points, axis=0), axis=1) > CHORD * radius) > 0.01)


def _on_sphere(points, radius):
    """The points of a path that lie near its sphere (a blown-up run leaves it: not drawn)."""
    if points is None:
        return None
    with np.errstate(over="ignore", invalid="ignore"):
        near = np.all(np.isfinite(points), axis=1) & (np.linalg.norm(points, axis=1) <= 1.5 * radius)
    return points[near] if near.any() else points[:1] * np.nan


def _sphere_panel(ax, sphere: Sphere):
    import matplotlib.patches

    radius = sphere.radius
    sphere = sphere._replace(curves=[c._replace(points=_on_sphere(c.points, radius), dense=_on_sphere(c.dense, radius),
                                                at=_on_sphere(c.at, radius)) for c in sphere.curves])
    everything = np.concatenate([c.points for c in sphere.curves] + [c.dense for c in sphere.curves
                                                                     if c.dense is not None])
    v, e1, e2 = _view_basis(everything[np.all(np.isfinite(everything), axis=1)],
                            [c.dense if c.dense is not None else c.points for c in sphere.curves])
    ax.add_patch(matplotlib.patches.Circle((0, 0), radius, facecolor="#f4f6fa", edgecolor="0.3", lw=1.0, zorder=0))
    if sphere.levels is not None:
        g = np.linspace(-1, 1, 301) * radius
        u, w = np.meshgrid(g, g)
        depth2 = radius**2 - u**2 - w**2
        inside = depth2 >= 0
        pts = u[..., None] * e1 + w[..., None] * e2 + np.sqrt(np.where(inside, depth2, 0.0))[..., None] * v
        values = np.where(inside, sphere.levels(pts), np.nan)
        lo, hi = np.nanmin(values), np.nanmax(values)
        if np.isfinite(lo) and hi - lo > 1e-12 * max(abs(hi), abs(lo), 1e-300):
            ax.contour(u, w, values, levels=np.linspace(lo, hi, 16)[1:-1], colors="0.6", linewidths=0.6,
                       linestyles="solid", zorder=1)
            ax.plot([], [], color="0.6", lw=0.6, label=sphere.level_label)
    for k, name in enumerate(sphere.axis_names):  # coordinate axes: dots where they pierce the near side
        for sign in (1, -1):
            p = np.zeros(3)
            p[k] = sign * radius
            if p @ v > 0:
                x, y = p @ e1, p @ e2
                ax.plot(x, y, "o", color="0.2", ms=3, zorder=3)
                ax.annotate(("+" if sign > 0 else "\u2212") + name, (x, y), textcoords="offset points",
                            xytext=(4, 4), fontsize=8, color="0.2", zorder=3)
    for label, point in sphere.marks:
        p = radius * np.asarray(point) / np.linalg.norm(point)
        ax.plot(p @ e1, p @ e2, "*", color="k", ms=9, zorder=6, alpha=1.0 if p @ v >= 0 else 0.4, label=label)
    for c in sphere.curves:
        line = c.dense if c.dense is not None else c.points
        line = _joined(line, radius)
        x, y, front = line @ e1, line @ e2, (line @ v) >= 0
        back = ~front & np.isfinite(x)
        ax.plot(np.where(back, x, np.nan), np.where(back, y, np.nan), color=c.color, lw=0.8, alpha=0.35, ls="--",
                zorder=2)
        ax.plot(np.where(front, x, np.nan), np.where(front, y, np.nan), color=c.color, lw=1.3, zorder=4,
                label=c.label)
        if c.dense is not None:  # the saved states themselves, as dots
            px, py = c.points @ e1, c.points @ e2
            ax.plot(px, py, ".", color=c.color, ms=2.5, alpha=0.7, zorder=4)
        ax.plot(c.points[0] @ e1, c.points[0] @ e2, "o", color=c.color, mec="k", ms=6, zorder=5)
        ax.plot(c.points[-1] @ e1, c.points[-1] @ e2, "s", color=c.color, mec="k", ms=5, zorder=5)
        if c.at is not None and len(c.at):
            ax.plot(c.at @ e1, c.at @ e2, "D", mfc="none", mec="k", ms=5, zorder=6)
    ax.plot([], [], "o", color="w", mec="k", ms=6, label="start")
    ax.plot([], [], "s", color="w", mec="k", ms=5, label="end")
    if any(c.at is not None and len(c.at) for c in sphere.curves):
        ax.plot([], [], "D", mfc="none", mec="k", ms=5, label="--save-at times")
    ax.set_aspect("equal")
    ax.set_xlim(-1.05 * radius, 1.05 * radius)
    ax.set_ylim(-1.05 * radius, 1.05 * radius)
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_title(sphere.title, fontsize=9.5)
    ax.legend(loc="upper center", fontsize=7, ncol=2, frameon=False, bbox_to_anchor=(0.5, -0.0))


def envelope(t, values, max_points: int = _MAX_POINTS):
    """(t, values) thinned to about ``max_points`` by keeping each bucket's largest |value|
    (a stride could skip the maximum)."""
    n = len(t)
    if n <= max_points:
        return t, values
    bucket = int(np.ceil(n / max_points))
    m = (n // bucket) * bucket
    with np.errstate(invalid="ignore"):
        mag = np.where(np.isfinite(values[:m]), np.abs(values[:m]), -1.0).reshape(-1, bucket)
    pick = np.arange(0, m, bucket) + np.argmax(mag, axis=1)
    pick = np.concatenate([pick, np.arange(m, n)])
    return t[pick], values[pick]


def _error_panel(ax, t, series, label, colors, maxima):
    """``series`` {name: errors (n,)} against t on a log scale, each with the summary's max."""
    lines = []
    top, bottom = 0.0, np.inf
    for (name, err), color in zip(series.items(), colors):
        tt, ee = envelope(np.asarray(t)[1:], np.asarray(err)[1:])  # the error at t = 0 is 0 by definition
        with np.errstate(invalid="ignore", over="ignore"):
            shown = np.maximum(np.abs(ee), _FLOOR)
        shown = np.where(np.isfinite(shown) & (shown < 1e100), shown, np.nan)
        (line,) = ax.semilogy(tt, shown, color=color, lw=1.0)
        lines.append((line, f"{name}: max {maxima[name]:.2e}" if maxima.get(name) is not None else name))
        finite = shown[np.isfinite(shown)]
        if finite.size:
            top, bottom = max(top, finite.max()), min(bottom, finite.min())
    ax.set_ylabel(label, fontsize=9)
    ax.grid(True, which="major", alpha=0.4)
    if top > 0:
        ax.set_ylim(max(_FLOOR / 2, min(bottom, top / 10) / 3), top * 3)
    ax.legend([ln for ln, _ in lines], [text for _, text in lines], loc="center left", bbox_to_anchor=(1.01, 0.5),
              fontsize=7.5, frameon=False)


PALETTE = ("tab:orange", "tab:purple", "tab:green", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def simulate_figure(t, spheres, error_groups, maxima, *, title="", t_label="time t"):
    """The figure of ``jaxsplit simulate``: ``spheres`` (list of ``Sphere``) on the left,
    ``error_groups`` [(axis label, {name: errors (n,)})] on the right against ``t`` (n,),
    ``maxima`` {name: the summary's max}. Returns a matplotlib Figure."""
    plt = _pyplot()
    n_sph, rows = len(spheres), len(error_groups)
    fig = plt.figure(figsize=(5.2 * n_sph + 7.6, 6.0), dpi=110)
    grid = fig.add_gridspec(rows, n_sph + 1, width_ratios=(1,) * n_sph + (1.45,), wspace=0.3, hspace=0.14,
                            left=0.01, right=0.83, top=0.87, bottom=0.1)
    for k, sphere in enumerate(spheres):
        _sphere_panel(fig.add_subplot(grid[:, k]), sphere)
    axes, colors = [], iter(PALETTE)
    for k, (label, series) in enumerate(error_groups):
        ax = fig.add_subplot(grid[k, n_sph], sharex=axes[0] if axes else None)
        chosen = ["tab:blue"] if label.startswith("distance") else [next(colors) for _ in series]
        _error_panel(ax, t, series, label, chosen, maxima)
        if k < rows - 1:
            ax.tick_params(labelbottom=False)
        axes.append(ax)
    axes[-1].set_xlabel(t_label)
    axes[0].set_title("errors against time (log scale)", fontsize=10)
    if title:
        fig.suptitle(title, fontsize=10.5)
    return fig


def sweep_figure(table, *, title="", order=None):
    """Errors of a sweep against the step size, one line per group of inertia ratios.

    ``table``: {"h": (N,), "group": (N,) labels, "<metric>": (N,)} for the metrics
    ``error``, ``energy_error``, ``casimir_error``: median (solid) and max (dashed) over the
    cases of each (group, h); ``order`` lists the groups in legend order."""
    plt = _pyplot()
    metrics = [("error", "error vs reference\nmax|x_n - x_ref|"), ("energy_error", "energy error\nmax|H/H0 - 1|"),
               ("casimir_error", "Casimir error\nmax|C/C0 - 1|")]
    metrics = [m for m in metrics if m[0] in table]
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics) + 2.6, 4.6), dpi=110, squeeze=False)
    axes = axes[0]
    groups = list(order) if order is not None else list(dict.fromkeys(table["group"].tolist()))
    h = np.asarray(table["h"])
    for ax, (key, label) in zip(axes, metrics):
        values = np.asarray(table[key], dtype=float)
        for g, color in zip(groups, PALETTE * (1 + len(groups) // len(PALETTE))):
            sel = table["group"] == g
            hs = np.unique(h[sel])
            med = [np.median(values[sel & (h == x)]) for x in hs]
            top = [np.max(values[sel & (h == x)]) for x in hs]
            shown = lambda v: np.maximum(np.asarray(v), _FLOOR)
            ax.loglog(hs, shown(med), "o-", color=color, ms=3.5, lw=1.2, label=g)
            ax.loglog(hs, shown(top), "--", color=color, lw=0.9, alpha=0.7)
        ticks = np.unique(h)
        if len(ticks) <= 8:  # label the step sizes themselves (log minor labels overlap)
            import matplotlib.ticker

            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xticks(ticks, [f"{x:.3g}" for x in ticks])
        ax.set_xlabel("step size h")
        ax.set_title(label, fontsize=9.5)
        ax.grid(True, which="major", alpha=0.4)
    axes[-1].plot([], [], "k-", label="median over states")
    axes[-1].plot([], [], "k--", label="max over states")
    axes[-1].legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10.5)
    fig.subplots_adjust(left=0.06, right=0.78, bottom=0.14, top=0.82, wspace=0.32)
    return fig


def save_figure(fig, fileobj) -> None:
    fig.savefig(fileobj, format="png")
    _pyplot().close(fig)
