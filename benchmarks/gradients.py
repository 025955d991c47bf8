"""What does a gradient through n steps cost in memory and time, per adjoint?

``integrate(..., adjoint=)`` with ``"store"`` (every step's residuals), ``"checkpoint"``
(√n blocks) and ``"reversible"`` (states rebuilt by stepping back, fused rotation
pullbacks) on two systems: the free body (Strang, Casimir split, the polynomial kernel as a
concrete run would pick it) and a heavy-top-like system (rotations of (m, Γ) and a gravity
kick m ← m + t·w·Γ×χ; the general kernel: the kick changes |m|). The loss is a weighted sum
of the final state; gradients with respect to the parameters and the initial state.

* memory: XLA's own account of the compiled gradient (``memory_analysis().temp_size_in_bytes``);
* time: gradient / forward wall time (median of interleaved rounds);
* agreement: max relative difference from the stored-trajectory gradient.

    python benchmarks/gradients.py [--quick]

Writes ``benchmarks/results/gradients.{md,json}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
from _common import header, interleaved, log, machine_info, write

import jaxsplit

ADJOINTS = ("store", "checkpoint", "reversible")
H = 0.01


class Kick(jaxsplit.AbstractFlow):
    """m ← m + t·w·Γ×χ: the exact flow of the potential w⟨Γ, χ⟩ of a heavy top (Γ fixed)."""

    chi: jax.Array
    weight: jax.Array

    def __call__(self, x, t):
        m, gamma = x
        return (m + t * self.weight * jnp.cross(gamma, self.chi), gamma)


def free_body():
    m0 = jnp.asarray(jaxsplit.STANDARD_CASE.m0)
    args = (jnp.asarray(jaxsplit.STANDARD_CASE.inertia), m0)

    def loss(adjoint, n):
        def f(inertia, m):
            step = jaxsplit.splitting(jaxsplit.RigidBody(inertia), "strang", "casimir", shift=1).for_run(m0, H)
            return jnp.sum(jaxsplit.integrate(step, m, H, n, adjoint=adjoint).final * jnp.arange(1.0, 4.0))
        return f

    return loss, args


def heavy_top():
    parts = ("momentum", "vector")
    args = (jnp.array([1.0, 1.2, 0.6]), jnp.array([0.0, 0.05, 0.3]), jnp.asarray(1.5),
            (jnp.array([0.3, -0.2, 1.1]), jnp.array([0.1, 0.2, 0.97])))

    def loss(adjoint, n):
        def f(inertia, chi, weight, x0):
            w = 1 / inertia
            flows = tuple(jaxsplit.AxisRotation(k, w[k], parts) for k in range(3)) + (Kick(chi, weight),)
            m, gamma = jaxsplit.integrate(jaxsplit.compose(flows, "strang"), x0, H, n, adjoint=adjoint).final
            return jnp.sum(m * jnp.arange(1.0, 4.0)) + jnp.sum(gamma**3)
        return f

    return loss, args


def relative(a, b):
    return max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y)))
               for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/gradients.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    counts = (1_000, 10_000) if quick else (1_000, 10_000, 100_000, 1_000_000)
    timed = 10_000 if quick else 100_000
    repeats = 3 if quick else 5
    rows = []
    for system, make in (("free body", free_body), ("heavy-top-like", heavy_top)):
        loss, args = make()
        argnums = tuple(range(len(args)))
        grads = {}
        for n in counts:
            row = {"system": system, "n_steps": n}
            for adjoint in ADJOINTS:
                fn = jax.jit(jax.grad(loss(adjoint, n), argnums=argnums))
                row[f"{adjoint}_temp_bytes"] = int(fn.lower(*args).compile().memory_analysis().temp_size_in_bytes)
                if n <= timed:
                    grads[adjoint, n] = fn(*args)
            for adjoint in ("checkpoint", "reversible"):
                if (adjoint, n) in grads:
                    row[f"{adjoint}_vs_store"] = relative(grads[adjoint, n], grads["store", n])
            log(f"{system}, n = {n}: memory {[row[f'{a}_temp_bytes'] for a in ADJOINTS]}")
            rows.append(row)
        forward = jax.jit(loss("store", timed))
        cases = {"forward": lambda: jax.block_until_ready(forward(*args))}
        for adjoint in ADJOINTS:
            fn = jax.jit(jax.grad(loss(adjoint, timed), argnums=argnums))
            jax.block_until_ready(fn(*args))
            cases[adjoint] = lambda fn=fn: jax.block_until_ready(fn(*args))
        cases["forward"]()
        times = interleaved(cases, repeats)
        for adjoint in ADJOINTS:
            out.setdefault("time_vs_forward", {})[f"{system}, {adjoint}"] = statistics.median(
                a / f for a, f in zip(times[adjoint], times["forward"]))
        out.setdefault("forward_s", {})[system] = statistics.median(times["forward"])
    out["rows"] = rows
    lines = header(out, "Gradients through n steps (`benchmarks/gradients.py`)")
    lines += ["XLA temporary memory of the compiled gradient (MiB) and, where run, the largest relative difference "
              "from the stored-trajectory gradient.", "",
              "| system | steps | store | checkpoint | reversible | checkpoint vs store | reversible vs store |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        mib = [f"{r[f'{a}_temp_bytes'] / 2**20:.3g}" for a in ADJOINTS]
        diffs = [f"{r[k]:.1e}" if k in r else "—" for k in ("checkpoint_vs_store", "reversible_vs_store")]
        lines.append(f"| {r['system']} | {r['n_steps']:,} | " + " | ".join(mib + diffs) + " |")
    lines += ["", f"Time of one gradient / one forward run at {timed:,} steps (median of {repeats} interleaved rounds):",
              "", "| system | forward | store | checkpoint | reversible |", "|---|---|---|---|---|"]
    for system in ("free body", "heavy-top-like"):
        ratios = [f"{out['time_vs_forward'][f'{system}, {a}']:.2f}×" for a in ADJOINTS]
        lines.append(f"| {system} | {out['forward_s'][system] * 1e3:.3g} ms | " + " | ".join(ratios) + " |")
    out["wall_s"] = time.perf_counter() - start
    lines += ["", f"Total wall time {out['wall_s']:.0f} s."]
    write("gradients", quick, out, lines)


if __name__ == "__main__":
    main()
