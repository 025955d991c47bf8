"""The fits' optimiser (``jaxsplit.explore._minimise``: Adam, then L-BFGS, one loop that evaluates
the loss and gradient at one place) against its peer, optax's Adam and L-BFGS with optax's zoom
line search (what the fits used before: three places evaluate the loss, so XLA compiles the
integrator three times), on the same fits, side by side in interleaved rounds.

Per fit and optimiser: the fit's wall time, the part of it XLA spent compiling (JAX's own
``/jax/core/compile/backend_compile_duration`` events), the loss and gradient evaluations (a
separate counting run), and how far the two optima are apart. Every round clears JAX's caches,
so every fit compiles, as a user's first fit does. Compiled as users compile (XLA's
optimisations on).

    python benchmarks/optimiser.py [--rounds 2] [--quick]

Writes ``benchmarks/results/optimiser.{md,json}``.
"""

import argparse
import collections
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import optax
from _common import finish, header, log, machine_info

import jaxsplit
import jaxsplit.explore._fit as fit_module
import jaxsplit.explore._fit_inertia as fit_inertia_module
from jaxsplit.explore._fit_spins import spectrum, trajectory
from jaxsplit.explore._minimise import minimise


def optax_minimise(residuals, params, adam_steps, adam_lr, lbfgs_iter, tol):
    """The peer: optax Adam (a scan), then optax L-BFGS with its zoom line search (a while loop),
    L-BFGS starting from Adam's last evaluation; the loss one jitted function (traced once)."""

    @jax.jit
    def loss(p):
        r = residuals(p)
        return jnp.mean(r * r)

    value_and_grad = jax.value_and_grad(loss)
    adam = optax.adam(adam_lr)

    def adam_step(carry, k):
        p, state, _, _ = carry
        value, grad = value_and_grad(p)
        updates, stepped = adam.update(grad, state, p)
        keep = lambda new, old: jax.tree_util.tree_map(lambda a, b: jnp.where(k < adam_steps, a, b), new, old)
        return (keep(optax.apply_updates(p, updates), p), keep(stepped, state), value, grad), None

    unset = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(value_and_grad, params))
    params, _, value, grad = jax.lax.scan(adam_step, (params, adam.init(params), *unset),
                                          jnp.arange(adam_steps + 1))[0]
    opt = optax.lbfgs()
    state = optax.tree_utils.tree_set(opt.init(params), value=value, grad=grad)

    def body(carry):
        p, state, k = carry
        value, grad = optax.tree_utils.tree_get(state, "value"), optax.tree_utils.tree_get(state, "grad")
        updates, state = opt.update(grad, state, p, value=value, grad=grad, value_fn=loss)
        return optax.apply_updates(p, updates), state, k + 1

    def cond(carry):
        _, state, k = carry
        gnorm = optax.tree_utils.tree_norm(optax.tree_utils.tree_get(state, "grad"))
        return (k == 0) | ((k < lbfgs_iter) & (gnorm >= tol))

    p, state, k = jax.lax.while_loop(cond, body, (params, state, 0))
    return p, k, optax.tree_utils.tree_get(state, "value")


OPTIMISERS = {"jaxsplit (one evaluation site)": minimise, "optax Adam + L-BFGS, zoom line search": optax_minimise}


def use(optimiser):
    fit_module.minimise = optimiser
    fit_inertia_module.minimise = optimiser


def counting(optimiser, counter):
    """``optimiser`` with every evaluation of the residuals counted at run time."""
    def counted(residuals, params, *args):
        def residuals_counted(p):
            jax.debug.callback(lambda: counter.__setitem__(0, counter[0] + 1))
            return residuals(p)
        return optimiser(residuals_counted, params, *args)
    return counted


def cases(quick: bool):
    square = jaxsplit.lattices.lattice("square", 4)
    truth = {"exchange": (1.0, 0.6), "anisotropy": 0.2, "field": (0.1, 0.0, 0.3)}
    start = {"exchange": (0.9, 0.7), "anisotropy": 0.1, "field": (0.0, 0.0, 0.2)}
    t = np.linspace(0.0, 3.0, 16)
    x0 = jaxsplit.spin_lattice(square).random_state(seed=4)
    observed = np.asarray(trajectory(square, truth, x0, t))
    observed = observed + 1e-3 * np.random.default_rng(0).standard_normal(observed.shape)
    out = {"spin lattice 4x4, trajectory (reversible adjoint)":
           lambda: jaxsplit.fit_couplings(square, t, observed, start, fixed={"anisotropic": 0.0}).couplings}
    inertia = np.array([1.3, 2.1, 2.9])
    m0 = np.random.default_rng(11).standard_normal(3)
    m0 /= np.linalg.norm(m0)
    t_body = np.linspace(0.0, 20.0, 200)
    m = jaxsplit.simulate_observations(inertia, m0, t_body, 1e-3, seed=12)
    energy = 0.5 * float(np.sum(m0**2 / inertia))
    out["rigid body, 200 observations (fit_inertia)"] = lambda: {
        "ratios": jaxsplit.fit_inertia(t_body, m, energy=energy, energy_sigma=1e-3 * energy).inertia_ratios}
    if not quick:
        chain = jaxsplit.lattices.lattice("chain", 12)
        up = jaxsplit.spin_lattice(chain).uniform()
        x0c = jaxsplit.spin_lattice(chain).perturbed(up, 0.3, seed=3)
        tc = 0.5 * np.arange(48)
        clean = spectrum(chain, {"exchange": 1.0, "field": 0.5, "anisotropy": 0.1}, x0c, tc)
        noisy = clean + 1e-3 * clean.max() * np.random.default_rng(1).standard_normal(clean.shape)
        out["spin chain 12, S(q, w)"] = lambda: jaxsplit.fit_couplings(
            chain, tc, noisy, {"exchange": 0.95, "field": 0.45}, fixed={"anisotropy": 0.1},
            target="structure-factor", x0=x0c).couplings
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="two fits, one round")
    args = parser.parse_args(argv)
    rounds = 1 if args.quick else args.rounds
    command = f"python benchmarks/optimiser.py --rounds {rounds}" + (" --quick" if args.quick else "")
    began = time.perf_counter()
    out = machine_info(command)
    compile_s = collections.Counter()
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, seconds, **_: compile_s.update({"s": seconds})
        if event == "/jax/core/compile/backend_compile_duration" else None)
    fits = cases(args.quick)
    rows = {(c, o): {"wall": [], "compile": []} for c in fits for o in OPTIMISERS}
    for r in range(rounds):
        for case, run in fits.items():
            for name, optimiser in OPTIMISERS.items():
                use(optimiser)
                jax.clear_caches()
                before = compile_s["s"]
                t0 = time.perf_counter()
                result = run()
                rows[case, name]["wall"].append(time.perf_counter() - t0)
                rows[case, name]["compile"].append(compile_s["s"] - before)
                rows[case, name]["result"] = {k: np.asarray(v).tolist() for k, v in result.items()}
                log(f"round {r}: {case}, {name}: {rows[case, name]['wall'][-1]:.1f} s")
    for case, run in fits.items():  # the evaluations, in a run of their own (the callback is not free)
        for name, optimiser in OPTIMISERS.items():
            counter = [0]
            use(counting(optimiser, counter))
            jax.clear_caches()
            run()
            rows[case, name]["evaluations"] = counter[0]
    use(minimise)
    mine, peer = OPTIMISERS
    lines = header(out, "The fits' optimiser against optax's (`benchmarks/optimiser.py`)")
    lines += [(f"Each fit {rounds} time(s), the optimisers alternating, JAX's caches cleared before each fit "
               "(every fit compiles); medians. Compile: XLA's backend compile time within the fit."), "",
              "| fit | optimiser | wall | of which compile | evaluations | fitted values (max difference between the two) |",
              "|---|---|---|---|---|---|"]
    summary = {}
    for case in fits:
        a, b = rows[case, mine]["result"], rows[case, peer]["result"]
        differ = max(float(np.max(np.abs(np.asarray(a[k]) - np.asarray(b[k])))) for k in a)
        for name in OPTIMISERS:
            row = rows[case, name]
            wall, comp = float(np.median(row["wall"])), float(np.median(row["compile"]))
            lines.append(f"| {case} | {name} | {wall:.1f} s | {comp:.1f} s | {row['evaluations']} | {differ:.1e} |")
        summary[case] = {"wall_ratio": float(np.median(rows[case, peer]["wall"]) / np.median(rows[case, mine]["wall"])),
                         "compile_ratio": float(np.median(rows[case, peer]["compile"])
                                                / np.median(rows[case, mine]["compile"])),
                         "max_difference": differ}
    lines += ["", "Peer / jaxsplit: " + "; ".join(f"{c}: wall {s['wall_ratio']:.2f}×, compile {s['compile_ratio']:.2f}×"
                                                  for c, s in summary.items())]
    out["rows"] = [{"fit": c, "optimiser": o, **v} for (c, o), v in rows.items()]
    out["summary"] = summary
    finish("optimiser", out, lines, began, args.quick)


if __name__ == "__main__":
    main()
