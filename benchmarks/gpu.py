"""Spin lattices on an accelerator: spin-steps per second at 10⁶, 10⁷ and 10⁸ spins against the
device's own copy bandwidth and a hand-fused JAX loop of the same algebra, run side by side.

Periodic simple-cubic Heisenberg lattice (J = 1), unit spins in random directions, Strang over
the six bond colours (10 colour flows per step in a run, ``spin_scale.SUB_FLOWS``), float64,
h = 0.01. Contenders, on the same device and the same initial state:

* jaxsplit: ``integrate(splitting(system, "strang", "bonds"), s0, h, n).final`` on the (N, 3)
  state as a user writes it;
* hand-fused JAX: ``_spin_kernels.fused_run``, one ``fori_loop`` over the (3, L, L, L) state,
  each colour flow inline (the speed target), checked to agree with jaxsplit to round-off.

Bandwidth: XLA's ``2·x`` on 2²⁷ float64 (1 GiB) on the device, one read + one write counted.
Bounds per spin-step as in ``spin_scale.py``: one read and one write of the 24-byte state per
colour flow (48 B × 10), and one pass per step (48 B).

Host-side construction of the lattice is timed too (the colouring is built on the host).
Each size appends its row to the record as soon as it is measured (a lease that ends early
keeps what finished). Also writes the optimised HLO of the free-body run at 10⁶ bodies
(jaxsplit and the hand-fused loop of ``throughput.py``) for reading off-device.

    python benchmarks/gpu.py [--sizes 100,216,464] [--hlo DIR]   # results/gpu-<backend>.{md,json}
"""

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import header, interleaved, log, machine_info, write
from _spin_kernels import fused_run
from spin_scale import STATE_BYTES, SUB_FLOWS, H, build

import jaxsplit

STEPS = {100: 40, 216: 20, 464: 10}


def copy_bandwidth(n=2**27):
    x = jnp.ones(n)
    twice = jax.jit(lambda a: 2.0 * a)
    twice(x).block_until_ready()
    return 2 * x.nbytes / min(interleaved({"copy": lambda: twice(x).block_until_ready()}, 5)["copy"])


def spin_row(size: int, bw: float) -> dict:
    t = time.perf_counter()
    _, step, s0 = build((size,) * 3)
    built = time.perf_counter() - t
    n = STEPS.get(size, 10)
    x = jnp.asarray(s0)
    cube = jnp.asarray(np.ascontiguousarray(s0.T).reshape(3, size, size, size))
    del s0
    fused = fused_run(1.0, H)
    ours = lambda: jaxsplit.integrate(step, x, H, n).final.block_until_ready()
    theirs = lambda: fused(cube, H, n).block_until_ready()
    t = time.perf_counter()
    got = ours()
    first = time.perf_counter() - t
    ref = theirs()
    diff = float(jnp.max(jnp.abs(got - ref.reshape(3, -1).T)))
    del got, ref
    times = interleaved({"jaxsplit": ours, "hand-fused JAX": theirs}, 3)
    n_spins = size**3
    rates = {k: n_spins * n / min(v) for k, v in times.items()}
    bound = bw / (2 * STATE_BYTES * SUB_FLOWS)
    return {"size": size, "n_spins": n_spins, "steps": n, "host_build_s": built, "first_call_s": first,
            "max_diff_vs_fused": diff, "rates": rates, "ratio_fused_over_jaxsplit": rates["hand-fused JAX"] /
            rates["jaxsplit"], "bound_rate": bound, "fraction_of_bound": rates["jaxsplit"] / bound,
            "one_pass_rate": bw / (2 * STATE_BYTES)}


def free_body_hlo(folder: Path):
    """The optimised programs of ``throughput.py``'s B = 10⁶ run: jaxsplit and the hand-fused loop."""
    import throughput

    m = jnp.asarray(throughput.states(10**6))
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.asarray(throughput.INERTIA), allow_nonphysical=True), "strang", "casimir", shift=1)
    ours = jax.jit(lambda m: jaxsplit.integrate(step, m, throughput.H, 2000).final)
    fused = throughput.fused_run(2000, throughput.polynomial)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "hlo-jaxsplit.txt").write_text(ours.lower(m).compile().as_text())
    (folder / "hlo-fused.txt").write_text(fused.lower(m, throughput.H).compile().as_text())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="100,216,464")
    parser.add_argument("--hlo", default="")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    out = machine_info("python benchmarks/gpu.py" + (f" --sizes {args.sizes}" if args.sizes != "100,216,464" else ""))
    out["devices"] = [str(d) for d in jax.devices()]
    out["copy_bandwidth_B_per_s"] = bw = copy_bandwidth()
    out["spins"] = []

    def record():
        lines = header(out, "Spin lattices on an accelerator (`benchmarks/gpu.py`)")
        lines += [(f"Devices: {', '.join(out['devices'])}. Copy bandwidth (XLA 2·x, 1 GiB, read + write): "
                  f"{bw / 1e9:.0f} GB/s. Simple-cubic Heisenberg, Strang over the bond colours, float64, h = {H}; "
                  "wall time, best of 3 interleaved rounds."), "",
                  ("| N spins | steps | host build (s) | first call (s) | jaxsplit spin-steps/s | hand-fused JAX | "
                  "hand-fused / jaxsplit | max diff | fraction of the per-flow bound | one-pass bound |"),
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in out["spins"]:
            lines.append(f"| {r['n_spins']:,} | {r['steps']} | {r['host_build_s']:.1f} | {r['first_call_s']:.1f} | "
                         f"{r['rates']['jaxsplit']:.3g} | {r['rates']['hand-fused JAX']:.3g} | "
                         f"{r['ratio_fused_over_jaxsplit']:.2f}× | {r['max_diff_vs_fused']:.1e} | "
                         f"{r['fraction_of_bound']:.1%} | {r['one_pass_rate']:.3g} |")
        out["wall_s"] = time.perf_counter() - start
        write("gpu", False, out, lines + ["", f"Total wall time {out['wall_s']:.0f} s."])

    if args.hlo:
        free_body_hlo(Path(args.hlo))
    for size in (int(s) for s in args.sizes.split(",")):
        log(f"spins {size}^3")
        out["spins"].append(spin_row(size, bw))
        record()


if __name__ == "__main__":
    main()
