"""Couplings of a spin lattice by gradients (issue 33, item 4): are hidden couplings recovered to
1 % from noisy synthetic data at full size, how long does a fit take, and what does the
gradient's memory do as the steps per observation grow (reversible adjoint against the
checkpointed intervals)?

Cases (``jaxsplit.fit_couplings``, Strang on the exact bond splitting, Adam 0 + L-BFGS):

* ``square``: 16×16 square lattice (256 spins), J per bond direction (x, y), uniaxial K along
  z and a field B (6 numbers), from a random state, 41 observations of every spin over
  t ∈ [0, 4] with noise σ = 1e-3;
* ``chain-xxz-dm``: a 64-site chain with J, the XXZ Δ, a DM vector along z and B along z,
  41 observations over t ∈ [0, 4], σ = 1e-3;
* ``spectrum``: S(q, ω) of a 48-site chain (J, B along z; K = 0.1 held) from a perturbed ferromagnet
  (cone 0.3 rad), 128 frames of dt = 0.5, noise 0.3 % of the largest intensity on every bin.

Memory: XLA's temporary memory of the compiled gradient of the square lattice's trajectory
misfit (10 observations) for 1 … 1000 steps per observation, per adjoint, and the two
adjoints' gradients compared.

    python benchmarks/fit_spins.py [--quick]

Writes ``benchmarks/results/fit_spins.{md,json}``.
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, log, machine_info

import jaxsplit
from jaxsplit.core._schemes import schemes
from jaxsplit.explore._fit import Model
from jaxsplit.explore._fit_spins import SpinCouplings, _all_params, spectrum, trajectory


def relative_errors(fitted, truth):
    return {k: float(np.linalg.norm(np.asarray(fitted[k]) - np.asarray(v)) / np.linalg.norm(v)) for k, v in truth.items()}


def trajectory_case(name, lattice, truth, start, fixed, t, noise, seed, adjoint):
    x0 = jaxsplit.spin_lattice(lattice).random_state(seed=seed)
    clean = np.asarray(trajectory(lattice, {**truth, **fixed}, x0, t, max_step=0.01))  # finer than the model
    noisy = clean + noise * np.random.default_rng(seed).standard_normal(clean.shape)
    f = jaxsplit.fit_couplings(lattice, t, noisy, start, fixed=fixed, adjoint=adjoint)
    return row(name, lattice, truth, f, len(t))


def row(name, lattice, truth, f, n_obs):
    errors = relative_errors(f.couplings, truth)
    log(f"{name}: {errors} in {f.seconds:.1f} s")
    return {"case": name, "n_sites": lattice.n_sites, "observations": n_obs, "target": f.target,
            "adjoint": f.adjoint, "truth": truth, "fitted": {k: np.asarray(v).tolist() for k, v in f.couplings.items()},
            "std": {k: np.asarray(v).tolist() for k, v in f.couplings_std.items()}, "relative_error": errors,
            "worst": max(errors.values()), "iterations": f.iterations, "seconds": f.seconds,
            "noise_sigma": f.noise_sigma, "undetermined": list(f.undetermined), "weak": list(f.weak),
            "gauge": list(f.gauge)}


def memory(counts, quick):
    lat = jaxsplit.lattices.lattice("square", 8 if quick else 16)
    family = SpinCouplings.build(lat, fixed={})
    params = _all_params(family, {"exchange": (1.0, 0.6), "anisotropy": 0.2, "field": (0.1, 0.0, 0.3)})
    x0 = jnp.asarray(jaxsplit.spin_lattice(lat).random_state(seed=4))
    n_obs = 10
    data = {"x0": x0, "dts": jnp.full(n_obs, 0.5), "fixed": None,
            # data away from the model (Σ|S_i|² is conserved: against zeros the gradient would be round-off)
            "observed": jnp.asarray(np.random.default_rng(0).normal(size=(n_obs + 1, lat.n_sites * 3)))}
    rows = []
    for n_sub in counts:
        row_ = {"steps_per_observation": n_sub, "total_steps": n_sub * n_obs, "n_sites": lat.n_sites}
        grads = {}
        for adjoint in ("reversible", "checkpoint"):
            model = Model(family, schemes.resolve("strang"), "bonds", (), n_sub, False, None, None, adjoint)

            def loss(p, model=model):
                r = model.residuals({"params": p, "x0": None}, data)
                return jnp.mean(r * r)

            fn = jax.jit(jax.grad(loss))
            start = time.perf_counter()
            compiled = fn.lower(params).compile()
            row_[f"{adjoint}_temp_bytes"] = int(compiled.memory_analysis().temp_size_in_bytes)
            row_[f"{adjoint}_compile_s"] = time.perf_counter() - start
            start = time.perf_counter()
            grads[adjoint] = jax.block_until_ready(compiled(params))
            row_[f"{adjoint}_gradient_s"] = time.perf_counter() - start
        a, b = (jax.flatten_util.ravel_pytree(grads[k])[0] for k in ("reversible", "checkpoint"))
        row_["gradient_difference"] = float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))
        log(f"memory {row_}")
        rows.append(row_)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    begin = time.perf_counter()
    out = machine_info("python benchmarks/fit_spins.py" + (" --quick" if args.quick else ""))
    t = np.linspace(0.0, 4.0, 41)
    square = jaxsplit.lattices.lattice("square", 8 if args.quick else 16)
    chain = jaxsplit.lattices.lattice("chain", 16 if args.quick else 64)
    rows = [
        trajectory_case("square", square, {"exchange": (1.0, 0.6), "anisotropy": 0.2, "field": (0.1, 0.0, 0.3)},
                        {"exchange": (0.9, 0.7), "anisotropy": 0.1, "field": (0.0, 0.0, 0.2)}, {}, t, 1e-3, 4,
                        "reversible"),
        trajectory_case("chain-xxz-dm", chain, {"exchange": 1.0, "anisotropic": 0.3, "dm": (0.0, 0.0, 0.2),
                                                "field": (0.0, 0.0, 0.3)},
                        {"exchange": 0.9, "anisotropic": 0.2, "dm": (0.0, 0.0, 0.1), "field": (0.0, 0.0, 0.2)}, {},
                        t, 1e-3, 5, "reversible"),
    ]
    spin_chain = jaxsplit.lattices.lattice("chain", 16 if args.quick else 48)
    system = jaxsplit.spin_lattice(spin_chain)
    x0 = system.perturbed(system.uniform(), 0.3, seed=3)
    ts = 0.5 * np.arange(64 if args.quick else 128)
    truth = {"exchange": 1.0, "field": 0.5}  # B along the axis n = z
    clean = spectrum(spin_chain, {**truth, "anisotropy": 0.1}, x0, ts, max_step=0.01)
    noisy = clean + 3e-3 * clean.max() * np.random.default_rng(1).standard_normal(clean.shape)
    f = jaxsplit.fit_couplings(spin_chain, ts, noisy, {"exchange": 0.95, "field": 0.45},
                               fixed={"anisotropy": 0.1}, target="structure-factor", x0=x0, max_step=0.05)
    rows.append(row("spectrum", spin_chain, truth, f, len(ts)))
    out["fits"] = rows
    out["memory"] = memory((1, 10, 100) if args.quick else (1, 10, 100, 1000), args.quick)
    lines = header(out, "Couplings of a spin lattice by gradients (`benchmarks/fit_spins.py`)")
    lines += ["Hidden couplings from noisy synthetic data (data integrated with steps of 0.01, the model with 0.05; "
              "Strang on the exact bond splitting; Adam 0 + L-BFGS; wall time includes compilation).", "",
              "| case | spins | data | fitted terms: relative error (fitted ± σ) | worst | iterations | wall |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        terms = "; ".join(f"{k} {r['relative_error'][k]:.1e} ({np.round(r['fitted'][k], 4).tolist()} ± "
                          f"{np.round(r['std'][k], 4).tolist()})" for k in r["truth"])
        data = f"{r['observations']} {'spin states' if r['target'] == 'trajectory' else 'frames -> S(q, w)'}"
        lines.append(f"| {r['case']} | {r['n_sites']} | {data} | {terms} | {r['worst']:.1e} | {r['iterations']} | "
                     f"{r['seconds']:.0f} s |")
    worst = max(r["worst"] for r in rows)
    lines += ["", f"Worst relative error {worst:.2e} (target 1e-2: {'met' if worst < 1e-2 else 'NOT met'}). "
              "Undetermined or weak combinations reported: "
              + (", ".join(f"{r['case']}: {r['undetermined'] + r['weak']}" for r in rows if r["undetermined"] + r["weak"])
                 or "none"), "",
              "The errors are bias from the model's step, not noise: σ (Gauss–Newton, noise only) is 3e-6 to 1e-5 for "
              "the trajectory fits and 2e-4 / 4e-4 for the spectrum, below the errors; Strang at the model's step 0.05 "
              "against data integrated at 0.01 shifts a frequency ω by about (ωh)²/24 (0.2 % at ω = 4.5). A smaller "
              "max_step or a higher-order scheme lowers it.", ""]
    lines += ["Memory of the compiled gradient (XLA temporary bytes) of the square lattice's trajectory misfit, "
              f"{out['memory'][0]['n_sites']} spins, 10 observations, against the steps per observation:", "",
              "| steps per observation | total steps | reversible (MiB) | checkpoint (MiB) | gradients differ by "
              "(relative) | gradient time reversible / checkpoint |", "|---|---|---|---|---|---|"]
    for m in out["memory"]:
        lines.append(f"| {m['steps_per_observation']} | {m['total_steps']} | {m['reversible_temp_bytes'] / 2**20:.2f} | "
                     f"{m['checkpoint_temp_bytes'] / 2**20:.2f} | {m['gradient_difference']:.1e} | "
                     f"{m['reversible_gradient_s']:.2f} s / {m['checkpoint_gradient_s']:.2f} s |")
    finish("fit_spins", out, lines, begin, args.quick)


if __name__ == "__main__":
    main()
