"""The spin-lattice figure of ``jaxsplit simulate``: the final spin configuration, energy
error and magnetisation against time, and S(q, ω) along a path through the Brillouin zone
with the linear spin-wave curve where this model has one (``spin_wave_curve``)."""

import io

import numpy as np

FREQUENCY_POINTS = 64  # fewer saved states: no S(q, ω) panel


def q_path(lattice):
    """(grid indices (P, d), tick positions, tick labels): Γ–X–M–Γ on square and simple-cubic
    (the kz = 0 plane), 0..2π on a chain, along the first reciprocal vector otherwise."""
    size = lattice.size
    if lattice.name in ("square", "simple-cubic"):
        lx, ly = size[0], size[1]
        half_x, half_y = lx // 2, ly // 2
        pts = [(m, 0) for m in range(half_x + 1)] + [(half_x, m) for m in range(1, half_y + 1)]
        steps = min(half_x, half_y)
        pts += [(round(half_x * k / steps), round(half_y * k / steps)) for k in range(steps - 1, -1, -1)]
        pts = [p + (0,) * (len(size) - 2) for p in pts]
        return np.array(pts), [0, half_x, half_x + half_y, len(pts) - 1], ["Γ", "X", "M", "Γ"]
    pts = [(m,) + (0,) * (len(size) - 1) for m in range(size[0] + 1)]
    pts[-1] = (0,) * len(size)
    return np.array(pts), [0, size[0] // 2, size[0]], ["0", "b₁/2", "b₁"]


def spin_wave_curve(parameters, q):
    """Linear spin-wave ω(q) for a hypercubic lattice with exchange only (and a field along the
    ordered axis for a ferromagnet), or None: FM ω = 2JS Σ_a (1 − cos q_a) + |B|, Néel AFM
    ω = 2|J| S d √(1 − γ²), γ = (1/d) Σ_a cos q_a."""
    if parameters["lattice"] not in ("chain", "square", "simple-cubic") or not parameters["periodic"]:
        return None
    if parameters["anisotropic"] or parameters["anisotropy"] or parameters["dm"] is not None:
        return None
    j, s = parameters["exchange"], parameters["spin_length"]
    b = np.linalg.norm(parameters["field"])
    d = q.shape[-1]
    if j > 0 and parameters["initial"] == "ferro":
        return 2 * j * s * np.sum(1 - np.cos(q), axis=-1) + b
    if j < 0 and parameters["initial"] == "neel" and b == 0:
        gamma = np.mean(np.cos(q), axis=-1)
        return 2 * abs(j) * s * d * np.sqrt(np.clip(1 - gamma**2, 0, None))
    return None


def spin_figure(system, t, states, energy, magnet, parameters, summary) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import jaxsplit

    lat = system.lattice
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.5), gridspec_kw={"hspace": 0.32})
    _spin_map(fig, axes[0, 0], lat, states[-1])
    ax = axes[0, 1]
    rel = (energy - energy[0]) / max(abs(energy[0]), 1e-300)
    ax.plot(t, rel, lw=0.8)
    ax.set_xlabel("t")
    ax.set_ylabel("(E(t) − E(0)) / |E(0)|")
    ax.set_title(f"energy error; max {summary['energy_max_relative_error']:.1e}", fontsize=9)
    ax = axes[1, 0]
    for k, c in enumerate("xyz"):
        ax.plot(t, magnet[:, k] / lat.n_sites, lw=0.8, label=f"M{c}/N")
    ax.set_xlabel("t")
    ax.set_ylabel("magnetisation per spin")
    ax.legend(fontsize=8)
    ax.set_title("total magnetisation", fontsize=9)
    ax = axes[1, 1]
    if len(t) >= FREQUENCY_POINTS:
        sqw = jaxsplit.structure_factor(states, lat, float(t[1] - t[0]))
        idx, ticks, labels = q_path(lat)
        intensity = np.asarray(sqw.intensity)[tuple(idx.T)]
        keep = sqw.omega >= 0
        image = np.log10(np.maximum(intensity[:, keep], 1e-12 * intensity.max()) + 1e-300).T
        ax.imshow(image, origin="lower", aspect="auto", cmap="magma",
                  extent=(-0.5, len(idx) - 0.5, sqw.omega[keep][0], sqw.omega[keep][-1]))
        q = sqw.q[tuple(idx.T)]
        curve = spin_wave_curve(parameters, q)
        nyquist = float(np.pi / (t[1] - t[0]))
        note = ""
        if curve is not None:
            ax.plot(np.arange(len(idx)), curve, "c--", lw=1.0, label="linear spin waves")
            ax.legend(fontsize=8, loc="upper right")
            ax.set_ylim(0, min(sqw.omega[keep][-1], 1.3 * max(float(np.max(curve)), sqw.resolution * 4)))
            if np.max(curve) > nyquist:
                note = f"\naliased: ω reaches {np.max(curve):.2g} > π/Δt = {nyquist:.2g}; lower --save-every"
                summary["aliased"] = True
        ax.set_xticks(ticks, labels)
        ax.set_ylabel("ω")
        ax.set_title(f"log10 S(q, ω) (Δω = {sqw.resolution:.2g}){note}", fontsize=9)
    else:
        ax.text(0.5, 0.5, f"S(q, ω) needs >= {FREQUENCY_POINTS} saved states\n(lower --save-every)",
                ha="center", va="center")
        ax.set_axis_off()
    title = (f"{parameters['lattice']} {'x'.join(map(str, parameters['size']))}, J = {parameters['exchange']:g}, "
             f"B = ({','.join(f'{b:g}' for b in parameters['field'])}); {summary['method']}"
             f"{' ' + summary['scheme'] if summary['scheme'] else ''}, h = {summary['dt']:g}")
    fig.suptitle(title, fontsize=10)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()


def _spin_map(fig, ax, lat, s):
    if lat.dimension == 1:
        for k, c in enumerate("xyz"):
            ax.plot(np.arange(lat.n_sites), s[:, k], ".-", ms=3, lw=0.6, label=f"S{c}")
        ax.set_xlabel("site")
        ax.legend(fontsize=8)
        ax.set_title("final spins", fontsize=9)
        return
    pos, spins = lat.positions, s
    if lat.dimension == 3:  # the first layer
        layer = np.isclose(pos[:, 2], pos[:, 2].min())
        pos, spins = pos[layer], s[layer]
    scale = np.max(np.linalg.norm(s, axis=-1))
    k = int(np.argmax(np.std(spins, axis=0)))  # the component that varies most shows the texture
    limit = max(float(np.max(np.abs(spins[:, k]))) / scale, 1e-3)
    sc = ax.scatter(pos[:, 0], pos[:, 1], c=spins[:, k] / scale, cmap="coolwarm", vmin=-limit, vmax=limit,
                    s=max(2.0, 2000.0 / len(pos)), marker="s")
    if len(pos) <= 1024:
        ax.quiver(pos[:, 0], pos[:, 1], spins[:, 0], spins[:, 1], angles="xy", scale_units="xy",
                  scale=2 * scale, width=0.002)
    ax.set_aspect("equal")
    fig.colorbar(sc, ax=ax, orientation="horizontal", fraction=0.05, pad=0.08, label=f"S_{'xyz'[k]} / S")
    ax.set_title(f"final spins: S_{'xyz'[k]} (colour)" + (", in-plane part (arrows)" if len(pos) <= 1024 else "")
                 + (", layer z = 0" if lat.dimension == 3 else ""), fontsize=9)
