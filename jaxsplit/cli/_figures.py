"""Figures for the command line (matplotlib, Agg backend, imported only when drawing).

``simulate_figure`` shows a trajectory on the momentum sphere |m| = |m0| (orthographic
view, with the level curves of the energy on the visible hemisphere) next to the relative
energy and Casimir errors (and, for a symmetric body, the error against the exact
solution) against time on log scales.
"""

import numpy as np

_FLOOR = 1e-17  # exact zeros (round-off luck) are drawn at this floor on the log scales
_MAX_POINTS = 20_000


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _view_basis(m: np.ndarray):
    """An oblique view direction v that sees most of the trajectory, and a screen basis."""
    mean = m.mean(axis=0)
    oblique = np.array([1.0, 0.8, 0.9]) / np.linalg.norm([1.0, 0.8, 0.9])
    norm = np.linalg.norm(mean)
    if norm > 1e-12:
        direction = mean / norm
        tilt = oblique - (oblique @ direction) * direction  # tilt the view off the mean a little
        tilt_norm = np.linalg.norm(tilt)
        v = direction if tilt_norm < 1e-12 else 0.8 * direction + 0.6 * tilt / tilt_norm
    else:
        v = oblique
    v /= np.linalg.norm(v)
    up = np.array([0.0, 0.0, 1.0])
    if abs(v @ up) > 0.95:
        up = np.array([0.0, 1.0, 0.0])
    e1 = np.cross(up, v)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(v, e1)
    return v, e1, e2


def _thin(*arrays):
    n = len(arrays[0])
    stride = max(1, int(np.ceil(n / _MAX_POINTS)))
    return [a[::stride] if a is not None else None for a in arrays]


def _sphere_panel(ax, m, inertia, radius):
    v, e1, e2 = _view_basis(m)
    # Energy on the visible hemisphere of the sphere of radius ``radius``.
    g = np.linspace(-1, 1, 401) * radius
    u, w = np.meshgrid(g, g)
    depth2 = radius**2 - u**2 - w**2
    inside = depth2 >= 0
    depth = np.sqrt(np.where(inside, depth2, 0.0))
    pts = u[..., None] * e1 + w[..., None] * e2 + depth[..., None] * v
    energy = 0.5 * np.sum(pts**2 / np.asarray(inertia), axis=-1)
    energy = np.where(inside, energy, np.nan)
    e_min, e_max = radius**2 / (2 * np.max(inertia)), radius**2 / (2 * np.min(inertia))
    ax.add_patch(__import__("matplotlib.patches", fromlist=["Circle"]).Circle(
        (0, 0), radius, facecolor="#f4f6fa", edgecolor="0.3", lw=1.0, zorder=0))
    if e_max - e_min > 1e-12 * e_max:
        levels = np.linspace(e_min, e_max, 16)[1:-1]
        ax.contour(u, w, energy, levels=levels, colors="0.55", linewidths=0.6, zorder=1)
        ax.plot([], [], color="0.55", lw=0.6, label="energy level curves")
    # Body axes: dots where they pierce the visible hemisphere.
    for k, name in enumerate(("m1", "m2", "m3")):
        for sign in (1, -1):
            p = np.zeros(3)
            p[k] = sign * radius
            if p @ v > 0:
                x, y = p @ e1, p @ e2
                ax.plot(x, y, "o", color="0.2", ms=3, zorder=3)
                ax.annotate(("+" if sign > 0 else "\u2212") + name, (x, y), textcoords="offset points",
                            xytext=(4, 4), fontsize=8, color="0.2", zorder=3)
    # Trajectory: solid in front, faint dashed behind.
    x, y, front = m @ e1, m @ e2, (m @ v) >= 0
    xf, yf = np.where(front, x, np.nan), np.where(front, y, np.nan)
    xb, yb = np.where(~front, x, np.nan), np.where(~front, y, np.nan)
    ax.plot(xb, yb, color="tab:blue", lw=0.8, alpha=0.35, ls="--", zorder=2,
            label="trajectory (far side)" if (~front).any() else None)
    ax.plot(xf, yf, color="tab:blue", lw=1.4, zorder=4, label="trajectory")
    ax.plot(x[0], y[0], "o", color="tab:green", ms=6, zorder=5, label="start")
    ax.plot(x[-1], y[-1], "s", color="tab:red", ms=5, zorder=5, label="end")
    ax.set_aspect("equal")
    ax.set_xlim(-1.08 * radius, 1.08 * radius)
    ax.set_ylim(-1.08 * radius, 1.3 * radius)
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_title(f"m on the sphere |m| = {radius:.4g}", fontsize=10)
    ax.legend(loc="upper center", fontsize=7, ncol=3, frameon=False, bbox_to_anchor=(0.5, 1.0))


def _error_panel(ax, t, err, label, color):
    if len(t) > 1:  # the error at t = 0 is zero by definition
        t, err = t[1:], err[1:]
    with np.errstate(invalid="ignore", over="ignore"):
        shown = np.maximum(np.abs(err), _FLOOR)
    shown = np.where(np.isfinite(shown) & (shown < 1e100), shown, np.nan)  # drawable values only
    ax.semilogy(t, shown, color=color, lw=1.0)
    ax.set_ylabel(label, fontsize=9)
    ax.grid(True, which="major", alpha=0.4)
    finite = shown[np.isfinite(shown)]
    if finite.size:
        top = finite.max()
        ax.set_ylim(max(_FLOOR / 2, min(finite.min(), top / 10) / 3), top * 3)
        ax.text(0.99, 0.04, f"max {np.nanmax(np.abs(err)):.2e}", transform=ax.transAxes,
                ha="right", va="bottom", fontsize=8, color="0.25",
                bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1})


def simulate_figure(t, m, energy_error, casimir_error, inertia, *, title="", exact_error=None):
    """The figure of ``jaxsplit simulate`` (returns a matplotlib Figure)."""
    plt = _pyplot()
    t, m, energy_error, casimir_error, exact_error = _thin(
        np.asarray(t), np.asarray(m), np.asarray(energy_error), np.asarray(casimir_error),
        None if exact_error is None else np.asarray(exact_error))
    rows = 3 if exact_error is not None else 2
    fig = plt.figure(figsize=(12, 5.6), dpi=110)
    grid = fig.add_gridspec(rows, 2, width_ratios=(1, 1.25), wspace=0.12, hspace=0.12)
    radius = float(np.linalg.norm(m[0])) or 1.0
    with np.errstate(over="ignore", invalid="ignore"):  # a blown-up run: draw its sane part
        sane = np.all(np.isfinite(m), axis=1) & (np.max(np.abs(m), axis=1) <= 1e3 * radius)
    _sphere_panel(fig.add_subplot(grid[:, 0]), m[sane] if sane.any() else m[:1], inertia, radius)
    panels = [(energy_error, "|H/H\u2080 \u2212 1|\nenergy error", "tab:orange"),
              (casimir_error, "|C/C\u2080 \u2212 1|\nCasimir error", "tab:purple")]
    if exact_error is not None:
        panels.append((exact_error, "max|m \u2212 m_exact|\nvs exact solution", "tab:blue"))
    axes = []
    for k, (err, label, color) in enumerate(panels):
        ax = fig.add_subplot(grid[k, 1], sharex=axes[0] if axes else None)
        _error_panel(ax, t, err, label, color)
        ax.yaxis.set_label_position("right")
        if k < rows - 1:
            ax.tick_params(labelbottom=False)
        axes.append(ax)
    axes[-1].set_xlabel("time t")
    axes[0].set_title("errors against time (log scale)", fontsize=10)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.02, right=0.9, top=0.88, bottom=0.1)
    return fig


def save_figure(fig, fileobj) -> None:
    fig.savefig(fileobj, format="png")
    _pyplot().close(fig)
