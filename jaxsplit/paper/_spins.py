"""The audit of spin integrators: the exact bond splitting and the schemes the field uses
(frozen-field sublattices, the symmetric sequential sweep of LAMMPS SPIN, the spherical
midpoint of Sunny.jl, Heun with renormalisation of VAMPIRE/UppASD), side by side on small
lattices (N <= 16).

For each (case, method) it MEASURES, at random states: the Poisson defect
max|DΦ Π DΦᵀ − Π∘Φ| by ``jacfwd`` at several h and its leading power (defect ∝ h^p); over a run
of T = 100 (h = 0.05) the largest relative energy error and its drift (slope × T), the
largest |S_i| error, the total magnetisation's error where the model conserves it; and the
order of the global error at T = 1 against a converged reference (Kahan–Li 8 on the exact
bond flows). Verdicts are computed from these numbers by the rules in ``VERDICTS`` (from
``_records``: round-off and structure floors), never typed in. ``run_spins_audit`` returns
the records and the files (``spins.json``, ``spins.md``, two figures) in memory;
``audit_spins`` writes them (``jaxsplit spins-audit``).

Compile cost: each (case, method) compiles one program (a scan of traced-length loops)
that serves both the long run and the order ladder, and one for the defects at every h.
"""

import io
import json
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..checks._order import fit_order
from ..checks._poisson import growth_exponent, poisson_defect
from ..core._errors import InputError
from ..lattices import lattice
from ..systems._spin_integrators import heun, spherical_midpoint
from ..systems._spin_lattice import spin_lattice
from ..systems._splitting import splitting
from ._records import ROUND_OFF, STRUCTURE_FLOOR

# name -> (lattice name, size, periodic, couplings): N <= 16, three geometries, all terms
CASES = {
    "ring-6": ("chain", 6, True, {"exchange": 1.0}),
    "square-4x4": ("square", 4, True, {"exchange": -1.0, "anisotropic": 0.2, "field": (0.0, 0.0, 0.3)}),
    "honeycomb-2x2": ("honeycomb", 2, True, {"exchange": 0.8, "dm": (0.1, 0.2, 0.3), "anisotropy": 0.3,
                                             "axis": (0.0, 0.6, 0.8), "field": (0.2, 0.0, 0.1)}),
}
METHODS = ("bonds", "sublattice", "sweep", "spherical-midpoint", "heun")
DEFECT_STEPS = (0.2, 0.1, 0.05, 0.025)
RUN_STEP, RUN_BLOCKS, RUN_PER_BLOCK = 0.05, 200, 10  # T = 100
ORDER_T, ORDER_PER_BLOCK = 1.0, (1, 2, 4, 8)  # h = 1/(200 k): 5e-3 .. 6e-4
ENERGY_DRIFT_SHARE = 0.2  # "bounded": the fitted drift over T is below this share of the largest error
INVARIANT_FLOOR_RELATIVE = 1e-10  # a relative invariant error below this is "conserved"

VERDICTS = {
    "Poisson map": f"every measured defect <= {ROUND_OFF:g} (round-off)",
    "not a Poisson map": f"some measured defect > {STRUCTURE_FLOOR:g}, growing as h^p",
    "energy conserved": f"largest relative energy error <= {INVARIANT_FLOOR_RELATIVE:g}",
    "energy bounded": f"energy error above that, with |drift·T| < {ENERGY_DRIFT_SHARE} × its largest value",
    "energy drifts": "otherwise",
    "undecided": "a measurement between the floors, or not finite",
}


def _system(case):
    name, size, periodic, couplings = CASES[case]
    return spin_lattice(lattice(name, size, periodic), **couplings)


def _step(system, method, scheme="strang"):
    if method in ("bonds", "sublattice", "sweep"):
        return splitting(system, scheme, method)
    if method == "spherical-midpoint":
        return spherical_midpoint(system)
    if method == "heun":
        return heun(system)
    raise InputError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")


def _runner(step):
    """One compiled program: RUN_BLOCKS blocks of a traced number of steps, every block end saved."""

    @jax.jit
    def run(x0, h, per_block):
        def block(x, _):
            x = jax.lax.fori_loop(0, per_block, lambda _, y: step(y, h), x)
            return x, x

        return jax.lax.scan(block, x0, length=RUN_BLOCKS)[1]

    return run


def poisson_column(case, method, seed=0):
    """The defects at ``DEFECT_STEPS`` (eager ``jacfwd``), their power p and the verdict."""
    system = _system(case)
    step = _step(system, method)
    x = system.random_state(seed)
    defect = jax.jit(lambda y, h: poisson_defect(step, system, y, h))  # one compilation, h traced
    defects = [float(defect(x, h)) for h in DEFECT_STEPS]
    worst = max(defects)
    if not all(map(math.isfinite, defects)):
        verdict = "undecided"
    elif worst <= ROUND_OFF:
        verdict = "Poisson map"
    elif worst > STRUCTURE_FLOOR:
        verdict = "not a Poisson map"
    else:
        verdict = "undecided"
    power = growth_exponent(DEFECT_STEPS, defects, floor=ROUND_OFF) if verdict == "not a Poisson map" else None
    return {"steps": list(DEFECT_STEPS), "defects": defects, "max": worst, "power": power, "verdict": verdict}


def _reference(case):
    system = _system(case)
    run = _runner(_step(system, "bonds", "kahan-li-8"))
    x0 = system.random_state(1)
    return run(x0, ORDER_T / (RUN_BLOCKS * 16), 16)[-1]


def run_columns(case, method, reference):
    """The long run (energy, |S_i|, magnetisation) and the order ladder of one method."""
    system = _system(case)
    run = _runner(_step(system, method))
    x0 = system.random_state(1)
    states = run(x0, RUN_STEP, RUN_PER_BLOCK)
    t = RUN_STEP * RUN_PER_BLOCK * np.arange(1, RUN_BLOCKS + 1)
    e0 = float(system.hamiltonian(x0))
    energy = np.asarray(jax.vmap(system.hamiltonian)(states)) - e0
    scale = max(abs(e0), 1.0)
    largest = float(np.max(np.abs(energy))) / scale
    drift = float(np.polyfit(t, energy, 1)[0] * t[-1]) / scale
    if largest <= INVARIANT_FLOOR_RELATIVE:
        energy_verdict = "energy conserved"
    elif abs(drift) < ENERGY_DRIFT_SHARE * largest:
        energy_verdict = "energy bounded"
    else:
        energy_verdict = "energy drifts"
    lengths = np.asarray(jnp.linalg.norm(states, axis=-1)) / np.asarray(system.spin_length)
    invariants = system.invariants()
    moment = next((k for k in invariants if k.startswith("magnetisation")), None)
    magnetisation = None
    if moment is not None:
        m = np.asarray(jax.vmap(invariants[moment])(states)) - np.asarray(invariants[moment](x0))
        magnetisation = {"invariant": moment, "max_error": float(np.max(np.abs(m)))}
    hs, errors = [], []
    for k in ORDER_PER_BLOCK:
        h = ORDER_T / (RUN_BLOCKS * k)
        hs.append(h)
        errors.append(float(jnp.max(jnp.abs(run(x0, h, k)[-1] - reference))))
    try:
        order = fit_order(hs, errors, min_points=3).order
    except InputError:
        order = None
    return {"energy": {"max_relative": largest, "drift_relative": drift, "verdict": energy_verdict,
                       "curve": (t.tolist(), (energy / scale).tolist())},
            "lengths": float(np.max(np.abs(lengths - 1))), "magnetisation": magnetisation,
            "order": {"steps": hs, "errors": errors, "order": order}}


def check_names(cases=None, methods=None) -> tuple[tuple, tuple]:
    """(cases, methods), all by default; unknown names refused (one line)."""
    cases = tuple(CASES) if cases is None else tuple(cases)
    methods = METHODS if methods is None else tuple(methods)
    for c in cases:
        if c not in CASES:
            raise InputError(f"unknown case {c!r}; choose from {', '.join(CASES)}")
    for m in methods:
        if m not in METHODS:
            raise InputError(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
    if not cases or not methods:
        raise InputError("name at least one case and one method (or none for all)")
    return cases, methods


def run_spins_audit(cases=None, methods=None, *, figures: bool = True) -> tuple[list[dict], dict]:
    """Run the audit (module docstring); return (records, {file name: bytes}), ``spins.json`` last.
    Needs float64. Writes nothing."""
    if not jax.config.jax_enable_x64:
        raise InputError("the spin audit measures at float64 round-off: enable jax_enable_x64 first")
    cases, methods = check_names(cases, methods)
    records = []
    for case in cases:
        reference = _reference(case)
        system = _system(case)
        for method in methods:
            start = time.perf_counter()
            record = {"case": case, "n_sites": system.n_sites, "method": method,
                      "poisson": poisson_column(case, method), **run_columns(case, method, reference)}
            record["seconds"] = time.perf_counter() - start
            records.append(record)
    files = {}
    if figures:
        files.update(_figures(records))
    files["spins.md"] = _report(records).encode("utf-8")
    slim = [{k: (v if k != "energy" else {kk: vv for kk, vv in v.items() if kk != "curve"}) for k, v in r.items()}
            for r in records]
    files["spins.json"] = json.dumps(slim, indent=2).encode("utf-8")
    return records, files


def output_names(figures: bool = True) -> tuple[str, ...]:
    return (("spins_defect.png", "spins_energy.png") if figures else ()) + ("spins.md", "spins.json")


def audit_spins(out_dir, cases=None, methods=None, *, figures: bool = True, force: bool = False) -> list[dict]:
    """Run the audit and write ``out_dir/spins.json``, ``spins.md`` and the figures through the
    command line's one writer (``cli._io.Outputs``: ``--force`` and the names checked before
    any work, atomic writes, the directory locked); the records and the directory written."""
    from ..cli import _io, _signals

    check_names(cases, methods)  # refused before any work
    with _io.Outputs(force=force) as outputs:
        out = outputs.directory(out_dir, "--out directory")
        for name in output_names(figures):
            outputs.file(out / name, "audit")
        records, files = run_spins_audit(cases, methods, figures=figures)
        with _signals.current().critical():
            for name, data in files.items():  # spins.json last
                outputs.write_bytes(out / name, data)
    return records, out


def _g(x, digits=2):
    return "—" if x is None else f"{x:.{digits}g}" if abs(x) >= 1e-3 or x == 0 else f"{x:.{digits}e}"


def _report(records) -> str:
    lines = ["# Spin integrators audited", "",
             ("Strang on each split; the implicit and explicit methods as they are. Defects by `jacfwd` at "
              f"h = {', '.join(map(str, DEFECT_STEPS))}; runs to T = {RUN_STEP * RUN_BLOCKS * RUN_PER_BLOCK:g} at "
              f"h = {RUN_STEP}; order at T = {ORDER_T:g} against Kahan–Li 8 on the exact bond flows."), "",
             ("| case | N | method | max Poisson defect | defect ∝ h^p | verdict | energy error (rel.) | drift·T "
              "| energy | max ‖S_i‖ error | magnetisation error | order |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        m = r["magnetisation"]
        lines.append(f"| {r['case']} | {r['n_sites']} | {r['method']} | {_g(r['poisson']['max'])} | "
                     f"{_g(r['poisson']['power'], 3)} | {r['poisson']['verdict']} | {_g(r['energy']['max_relative'])} | "
                     f"{_g(r['energy']['drift_relative'])} | {r['energy']['verdict']} | {_g(r['lengths'])} | "
                     f"{'not conserved by H' if m is None else _g(m['max_error'])} | {_g(r['order']['order'], 3)} |")
    lines += ["", "Verdict rules:", ""] + [f"* **{k}**: {v}" for k, v in VERDICTS.items()]
    return "\n".join(lines) + "\n"


def _figures(records) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in records))
    out = {}
    for name, draw in (("spins_defect.png", _draw_defects), ("spins_energy.png", _draw_energy)):
        fig, axes = plt.subplots(1, len(cases), figsize=(4.4 * len(cases), 3.6), squeeze=False,
                                 gridspec_kw={"wspace": 0.35})
        for ax, case in zip(axes[0], cases):
            draw(ax, [r for r in records if r["case"] == case])
            ax.set_title(case, fontsize=9)
        axes[0][-1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        out[name] = buffer.getvalue()
    return out


def _draw_defects(ax, rows):
    for r in rows:
        ax.loglog(r["poisson"]["steps"], np.maximum(r["poisson"]["defects"], 1e-17), "o-", ms=3, label=r["method"])
    ax.axhline(ROUND_OFF, color="k", lw=0.6, ls=":")
    ax.set_xticks(DEFECT_STEPS, [f"{h:g}" for h in DEFECT_STEPS])
    ax.xaxis.set_minor_formatter(_null_formatter())
    ax.set_xlabel("h")
    ax.set_ylabel("Poisson defect (jacfwd)")


def _null_formatter():
    import matplotlib.ticker

    return matplotlib.ticker.NullFormatter()


def _draw_energy(ax, rows):
    for r in rows:
        t, e = r["energy"]["curve"]
        ax.semilogy(t, np.maximum(np.abs(e), 1e-17), lw=0.8, label=r["method"])
    ax.set_xlabel("t")
    ax.set_ylabel("|relative energy error|")
