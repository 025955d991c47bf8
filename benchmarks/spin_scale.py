"""Spin lattices at scale: how many spin-steps per second does jaxsplit reach at N = 10⁵, 10⁶,
10⁷ spins, how far is that from the machine's memory bandwidth, and what does laying the
lattice over 4 devices or 2 processes cost?

Periodic simple-cubic Heisenberg lattice (J = 1, no field), unit spins in random directions,
``splitting(system, "strang", "bonds")``, float64, h = 0.01, run by ``integrate(step, s0, h, n)``.
One Strang step over the six colours is the word c1(h/2) … c5(h/2) c6(h) c5(h/2) … c1(h/2)
(11 colour flows); consecutive steps share c1 (first-same-as-last), so a run applies
SUB_FLOWS = 10 colour flows per step.

Bandwidth. A STREAM-like copy in the same run (``np.copyto`` of 2²⁵ float64 and XLA's
``2·x`` on the same bytes; bytes counted as STREAM does, one read + one write) gives the
copy bandwidth BW. The state is 24 B per spin. Bounds per spin-step:

* the acceptance bound: one read and one write of the state per sub-flow, 48 B × SUB_FLOWS,
  rate BW / (48 · SUB_FLOWS);
* the one-pass-per-step bound: one read and one write of the state per step, 48 B, rate BW / 48.

Bytes moved per spin-step are stated two ways: the flow's own model (per site and colour flow:
its spin 24 B read, its partner's spin 24 B read (a gather), its coupling 8 B and its partner
index 4 B read, 24 B written: 84 B, × SUB_FLOWS) and XLA's cost analysis of one compiled step
("bytes accessed", per spin).

Where the time goes at 10⁶ (``profile``): one colour flow (``BondExchange``) against its parts
run alone, each compiled by itself: the partner gather ``jnp.take``, the rotation ``turn`` with
a given angle vector, and a copy of the state.

Sharded (``--child devices``, a child process with ``--xla_force_host_platform_device_count=4``;
``--child processes`` under ``python -m jaxsplit.launch -n 2``): a 104 × 98 × 98 lattice
(998,816 spins; 26 planes per device so that a slab's colouring is the same on every device,
which the halo program needs) on one device, laid out by ``jaxsplit.distributed.shard`` over 4
devices and partitioned by XLA (GSPMD: it all-gathers the state before each colour's partner
gather), and by a ``shard_map`` program with explicit halo exchange (``lax.ppermute`` of one
boundary plane each way before every colour flow, the library's own flows applied to the slab
and its two halo planes: ``halo_step``). Max |difference| to one device is recorded. The 4
forced devices share this machine's 2 cores: no speed-up is possible, the overhead is the point.

XLA's CPU tuning: ``jaxsplit.tune_cpu()`` (512-bit vectors, recorded as ``XLA_FLAGS``) in this
process and its children, as the command line and ``spins.py`` run; it measured 10-25 % less CPU
time per colour flow at 32³ than XLA's default width (one interleaved run, 2026-11-27).

Timing: the machine is shared (2 cores, other engineers' jobs): every round runs every contender
once (interleaved), a time is the minimum over rounds of CPU time (``time.process_time``: all
threads of this process; every process of a multi-process run summed) and of wall time.

    python benchmarks/spin_scale.py            # writes results/spin_scale.{md,json}
    python benchmarks/spin_scale.py --quick    # 10⁴–10⁵ spins, results/spin_scale-quick.*
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SUB_FLOWS = 10  # colour flows per Strang step in a run (11 in the word, first-same-as-last merges one)
STATE_BYTES = 24  # per spin, float64
MODEL_BYTES = 24 + 24 + 8 + 4 + 24  # per site and colour flow (module docstring)
H = 0.01
SHARD_SIZE = (104, 98, 98)


def _setup():
    import jaxsplit

    jaxsplit.tune_cpu()  # 512-bit vectors, as the CLI and benchmarks/spins.py (before JAX starts its backend)
    import jax

    jax.config.update("jax_enable_x64", True)


def build(size):
    import jaxsplit
    from jaxsplit.lattices import lattice

    system = jaxsplit.spin_lattice(lattice("simple-cubic", size), exchange=1.0)
    step = jaxsplit.splitting(system, "strang", "bonds")
    rng = __import__("numpy").random.default_rng(0)
    v = rng.normal(size=(system.n_sites, 3))
    s0 = v / __import__("numpy").linalg.norm(v, axis=-1, keepdims=True)
    return system, step, s0


def timed(fn, rounds: int, names=None):
    """{name: (min CPU s, min wall s)} over interleaved rounds of the callables in ``fn``."""
    cpu, wall = {k: [] for k in fn}, {k: [] for k in fn}
    for _ in range(rounds):
        for k, f in fn.items():
            c, w = time.process_time(), time.perf_counter()
            f()
            cpu[k].append(time.process_time() - c)
            wall[k].append(time.perf_counter() - w)
    return {k: (min(cpu[k]), min(wall[k])) for k in fn}


# --------------------------------------------------------------------------- bandwidth
def copy_bandwidth(n=2**25, rounds=5):
    """Bytes per second of a copy (one read + one write counted), NumPy and XLA."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    src = np.random.default_rng(0).random(n)
    dst = np.empty_like(src)
    x = jnp.asarray(src)
    twice = jax.jit(lambda a: 2.0 * a)
    twice(x).block_until_ready()
    fns = {"numpy copyto": lambda: np.copyto(dst, src), "xla 2*x": lambda: twice(x).block_until_ready()}
    best = timed(fns, rounds)
    return {f"{k} ({clock})": 2 * src.nbytes / v[i] for k, v in best.items() for i, clock in enumerate(("CPU", "wall"))}


# --------------------------------------------------------------------------- one device
def throughput(size, n_steps, rounds):
    import jax
    import jax.numpy as jnp

    import jaxsplit

    system, step, s0 = build(size)
    x = jnp.asarray(s0)
    run = lambda: jaxsplit.integrate(step, x, H, n_steps).final.block_until_ready()  # noqa: E731
    c, w = time.process_time(), time.perf_counter()
    run()  # compiles
    first = (time.process_time() - c, time.perf_counter() - w)
    best = timed({"run": run}, rounds)["run"]
    n = system.n_sites
    one = jax.jit(lambda s: step(s, H)).lower(x).compile()
    analysis = one.cost_analysis()
    analysis = analysis[0] if isinstance(analysis, list) else analysis
    xla_bytes = float(analysis.get("bytes accessed", float("nan"))) / n
    return {"size": list(size), "n_spins": n, "n_steps": n_steps, "rounds": rounds, "first_call_s": first,
            "cpu_s": best[0], "wall_s": best[1], "rate_cpu": n * n_steps / best[0], "rate_wall": n * n_steps / best[1],
            "xla_bytes_per_spin_step": xla_bytes, "model_bytes_per_spin_step": MODEL_BYTES * SUB_FLOWS}


def profile(size, rounds):
    """One colour flow against its parts, each compiled alone, at ``size``."""
    import jax
    import jax.numpy as jnp

    from jaxsplit.systems._spin_flows import turn

    import numpy as np

    import jaxsplit
    from jaxsplit.lattices import lattice

    system, step, s0 = build(size)
    x = jnp.asarray(s0)
    pair_flow = step.flows[0]  # the fast path's colour flow (systems/_spin_pairs.py, components first)
    # the gather path's colour flow: the same lattice with one exchange value per bond
    cubic = lattice("simple-cubic", size)
    gather = jaxsplit.spin_lattice(cubic, exchange=np.full(cubic.n_bonds, 1.0))
    flow = jaxsplit.splitting(gather, "strang", "bonds").flows[0]
    partner = jnp.asarray(flow.partner.array)
    omega = jnp.asarray(0.01 * s0[::-1].copy())

    def turn_components(s, w):  # the same formula on (3, N): components first, sites along the vector lanes
        phi = jnp.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2] + jnp.finfo(w.dtype).tiny)
        sn, c = jnp.sin(phi / 2), jnp.cos(phi / 2)
        a = (sn + sn) / phi
        wx = jnp.stack([w[1] * s[2] - w[2] * s[1], w[2] * s[0] - w[0] * s[2], w[0] * s[1] - w[1] * s[0]])
        wwx = jnp.stack([w[1] * wx[2] - w[2] * wx[1], w[2] * wx[0] - w[0] * wx[2], w[0] * wx[1] - w[1] * wx[0]])
        return s + ((a * c) * wx + (0.5 * a * a) * wwx)

    fns = {"colour flow, fast path (PairExchange; alone it converts to components first and back)": jax.jit(lambda s: pair_flow(s, 0.005)),
           "colour flow, gather path (BondExchange)": jax.jit(lambda s: flow(s, 0.005)),
           "partner gather jnp.take": jax.jit(lambda s: jnp.take(s, partner, axis=0)),
           "turn(s, ω), ω given": jax.jit(lambda s, w: turn(s, w)),
           "same turn on (3, N), components first": jax.jit(turn_components),
           "state copy 2*s": jax.jit(lambda s: 2.0 * s)}
    args = {k: ((x, omega) if "turn" in k else (x,)) for k in fns}
    args["same turn on (3, N), components first"] = (x.T.copy(), omega.T.copy())
    for k, f in fns.items():
        f(*args[k]).block_until_ready()
    best = timed({k: (lambda f=f, a=args[k]: f(*a).block_until_ready()) for k, f in fns.items()}, rounds)
    n = system.n_sites
    return {k: {"ns_per_site": 1e9 * v[1] / n, "cpu_ns_per_site": 1e9 * v[0] / n} for k, v in best.items()}


# --------------------------------------------------------------------------- sharded
def halo_step(system, scheme, mesh):
    """The step of ``system`` as a program for one slab inside ``shard_map``: every flow of the
    system's own ``bonds`` split, built on the slab and one halo plane each side, preceded by
    the exchange of those planes with the neighbouring slabs (``lax.ppermute``). Needs a
    colouring that repeats from slab to slab (an even number of planes per slab) and
    couplings that do (a uniform lattice)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxsplit
    from jaxsplit.core._flows import AbstractFlow
    from jaxsplit.lattices._graph import Lattice

    lat, n_dev, axis = system.lattice, mesh.devices.size, mesh.axis_names[0]
    lx = lat.shape[0]
    plane, thick = lat.n_sites // lx, lx // n_dev
    if lx % n_dev or thick % 2 or thick < 2:
        raise ValueError(f"halo_step needs an even number of planes per device, got {lx} planes over {n_dev}")
    planes = [(p - 1) % lx for p in range(thick + 2)]  # slab 0 and its halos; the others are translates
    sites = np.concatenate([np.arange(q * plane, (q + 1) * plane) for q in planes])
    local = np.full(lat.n_sites, -1)
    local[sites] = np.arange(len(sites))
    keep = (local[lat.bonds[:, 0]] >= 0) & (local[lat.bonds[:, 1]] >= 0)
    renumber = np.full(lat.n_bonds, -1)
    renumber[keep] = np.arange(int(keep.sum()))
    colours = tuple(renumber[c][keep[c]] for c in lat.colours)
    window = Lattice("graph", (), False, lat.positions[sites], local[lat.bonds[keep]], (len(sites),), colours)
    windowed = jaxsplit.spin_lattice(window, exchange=system.exchange, field=system.field)

    class Halo(AbstractFlow):
        inner: AbstractFlow
        k: int = eqx.field(static=True)

        def __call__(self, state, t):
            k = self.k
            after = jax.lax.ppermute(state[:k], axis, [(i, (i - 1) % n_dev) for i in range(n_dev)])
            before = jax.lax.ppermute(state[-k:], axis, [(i, (i + 1) % n_dev) for i in range(n_dev)])
            return self.inner(jnp.concatenate([before, state, after]), t)[k:-k]

        @property
        def is_group(self):
            return self.inner.is_group

    return jaxsplit.compose(tuple(Halo(f, plane) for f in windowed.bonds_split()), scheme)


def child_devices(n_steps, rounds):
    import functools

    import jax
    import numpy as np
    from jax.sharding import PartitionSpec as P

    import jaxsplit
    from jaxsplit import distributed

    system, step, s0 = build(SHARD_SIZE)
    mesh = distributed.mesh()
    xs = distributed.shard(s0, mesh)
    x1 = jax.device_put(s0, jax.devices()[0])
    local = halo_step(system, "strang", mesh)

    @functools.partial(jax.jit, static_argnames="n")
    def halo_run(x, n):
        f = lambda s: jaxsplit.integrate(local, s, H, n).final  # noqa: E731
        return jax.shard_map(f, mesh=mesh, in_specs=P(mesh.axis_names[0]), out_specs=P(mesh.axis_names[0]),
                             check_vma=False)(x)

    fns = {"one device": lambda: jaxsplit.integrate(step, x1, H, n_steps).final,
           "4 devices, GSPMD (jaxsplit.distributed.shard)": lambda: jaxsplit.integrate(step, xs, H, n_steps).final,
           "4 devices, shard_map + ppermute halo": lambda: halo_run(xs, n_steps)}
    results = {k: np.asarray(f()) for k, f in fns.items()}  # compiles
    base = results["one device"]
    best = timed({k: (lambda f=f: f().block_until_ready()) for k, f in fns.items()}, rounds)
    return {"n_spins": system.n_sites, "size": list(SHARD_SIZE), "n_steps": n_steps, "rounds": rounds,
            "devices": len(jax.devices()),
            "rows": {k: {"cpu_s": v[0], "wall_s": v[1], "max_diff": float(np.max(np.abs(results[k] - base)))}
                     for k, v in best.items()}}


def child_processes(n_steps, rounds, path):
    rank, n = __import__("jaxsplit.distributed", fromlist=["x"]).initialize_from_env()
    _setup()
    import jax
    import numpy as np
    from jax.experimental import multihost_utils

    import jaxsplit
    from jaxsplit import distributed

    system, step, s0 = build(SHARD_SIZE)
    xs = distributed.shard(s0)
    run = lambda: jaxsplit.integrate(step, xs, H, n_steps).final  # noqa: E731
    final = run()
    best = timed({"run": lambda: run().block_until_ready()}, rounds)["run"]
    cpus = multihost_utils.process_allgather(np.array([best[0], best[1]]))
    whole = np.asarray(multihost_utils.process_allgather(final, tiled=True))
    if rank == 0:
        np.save(path + ".npy", whole)
        Path(path).write_text(json.dumps({"processes": n, "devices": len(jax.devices()), "n_spins": system.n_sites,
                                          "n_steps": n_steps, "rounds": rounds,
                                          "cpu_s_each": np.asarray(cpus)[:, 0].tolist(),
                                          "wall_s_each": np.asarray(cpus)[:, 1].tolist()}))


def _child(args_list, env_extra=None, launcher=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    env.update(env_extra or {})
    cmd = [sys.executable, str(Path(__file__).resolve()), *args_list]
    if launcher:
        cmd = [sys.executable, "-m", "jaxsplit.launch", "-n", str(launcher), "--", str(Path(__file__).resolve()),
               *args_list]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False, cwd=ROOT)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr[-3000:]}")
    return proc.stdout


# --------------------------------------------------------------------------- main
def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--child", choices=("devices", "processes"))
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", default="")
    args = parser.parse_args()
    if args.child == "processes":
        child_processes(args.steps, args.rounds, args.out)
        return
    _setup()
    if args.child == "devices":
        print(json.dumps(child_devices(args.steps, args.rounds)))
        return
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import _common

    start = time.perf_counter()
    command = "python benchmarks/spin_scale.py" + (" --quick" if args.quick else "")
    out = _common.machine_info(command)
    out["gpu"] = "no GPU is lent to this task: every figure is a CPU figure (JAX CPU backend)"
    bw = copy_bandwidth()
    out["copy_bandwidth_B_per_s"] = bw
    peak = max(v for k, v in bw.items() if "CPU" in k)  # CPU time: the core's own rate, as the spin rates
    plan = [((22,) * 3, 20, 3), ((46,) * 3, 10, 3)] if args.quick else [
        ((46,) * 3, 20, 3), ((100,) * 3, 4, 3), ((216,) * 3, 1, 2)]
    out["throughput"] = []
    for size, n_steps, rounds in plan:
        _common.log(f"throughput {size}")
        row = throughput(size, n_steps, rounds)
        row["bound_rate"] = peak / (2 * STATE_BYTES * SUB_FLOWS)
        row["one_pass_rate"] = peak / (2 * STATE_BYTES)
        out["throughput"].append(row)
    prof_size = (46,) * 3 if args.quick else (100,) * 3
    _common.log("profile")
    out["profile"] = {"size": list(prof_size), "rows": profile(prof_size, 3)}
    steps = 1 if args.quick else 3
    _common.log("4 devices")
    out["devices"] = json.loads(_child(["--child", "devices", "--steps", str(steps)],
                                       {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}).strip().splitlines()[-1])
    _common.log("2 processes")
    with tempfile.TemporaryDirectory() as tmp:
        proc = {}
        for n in (1, 2):
            path = os.path.join(tmp, f"p{n}.json")
            _child(["--child", "processes", "--steps", str(steps), "--out", path], launcher=n)
            proc[n] = json.loads(Path(path).read_text())
            proc[n]["final"] = path + ".npy"
        import numpy as np

        diff = float(np.max(np.abs(np.load(proc[1]["final"]) - np.load(proc[2]["final"]))))
        for n in (1, 2):
            proc[n].pop("final")
    out["processes"] = {"one": proc[1], "two": proc[2], "max_diff": diff}

    lines = _common.header(out, "Spin lattices at scale: simple-cubic Heisenberg, Strang, float64")
    lines += [out["gpu"] + ".", "",
              "Copy bandwidth (STREAM-like, one read + one write counted): " + ", ".join(
                  f"{k} {v / 1e9:.2f} GB/s" for k, v in bw.items()) + f"; BW = {peak / 1e9:.2f} GB/s (the larger by CPU time, "
              "the clock of the spin rates below; wall times on this shared machine include waiting for a core).", "",
              f"Bounds per spin-step: acceptance bound 2 × {STATE_BYTES} B × {SUB_FLOWS} sub-flows = "
              f"{2 * STATE_BYTES * SUB_FLOWS} B (rate BW/{2 * STATE_BYTES * SUB_FLOWS}); one pass per step "
              f"{2 * STATE_BYTES} B (rate BW/{2 * STATE_BYTES}).", "",
              "| N spins | steps × rounds | first call (s, CPU/wall) | best CPU s | spin-steps/s (CPU) | spin-steps/s "
              "(wall) | B/spin-step (model; XLA) | acceptance bound (spin-steps/s) | fraction of it (CPU rate) | "
              "one-pass bound | distance to it |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in out["throughput"]:
        lines.append(f"| {r['n_spins']:,} | {r['n_steps']} × {r['rounds']} | {r['first_call_s'][0]:.1f} / "
                     f"{r['first_call_s'][1]:.1f} | {r['cpu_s']:.3f} | {r['rate_cpu']:.3g} | {r['rate_wall']:.3g} | "
                     f"{r['model_bytes_per_spin_step']}; {r['xla_bytes_per_spin_step']:.0f} | {r['bound_rate']:.3g} | "
                     f"{r['rate_cpu'] / r['bound_rate']:.1%} | {r['one_pass_rate']:.3g} | "
                     f"{r['one_pass_rate'] / r['rate_cpu']:.0f}× |")
    lines += ["", f"Where one colour flow's time goes at {out['profile']['size'][0]}³ (each part compiled alone, "
              "min of 3 rounds, ns per site):", "", "| kernel | ns/site (CPU, all threads) | ns/site (wall) | "
              "GB/s at 48 B/site (CPU) |", "|---|---|---|---|"]
    for k, v in out["profile"]["rows"].items():
        lines.append(f"| {k} | {v['cpu_ns_per_site']:.2f} | {v['ns_per_site']:.2f} | {48 / v['cpu_ns_per_site']:.2f} |")
    d = out["devices"]
    base = d["rows"]["one device"]
    lines += ["", f"Sharded over {d['devices']} forced CPU devices (one process, 2 shared cores), "
              f"{'x'.join(map(str, d['size']))} = {d['n_spins']:,} spins, {d['n_steps']} steps, min of "
              f"{d['rounds']} interleaved rounds:", "",
              "| layout | CPU s | wall s | CPU / one device | wall / one device | max abs diff to one device |",
              "|---|---|---|---|---|---|"]
    for k, v in d["rows"].items():
        lines.append(f"| {k} | {v['cpu_s']:.3f} | {v['wall_s']:.3f} | {v['cpu_s'] / base['cpu_s']:.2f} | "
                     f"{v['wall_s'] / base['wall_s']:.2f} | {v['max_diff']:.1e} |")
    p1, p2 = out["processes"]["one"], out["processes"]["two"]
    lines += ["", f"Over 2 processes (`python -m jaxsplit.launch -n 2`, one CPU device each, gloo collectives on "
              f"127.0.0.1), same lattice and steps, min of {p2['rounds']} rounds:", "",
              "| run | CPU s per process | CPU s summed | wall s (slowest) | summed CPU / 1 process | wall / 1 process |",
              "|---|---|---|---|---|---|"]
    for name, p in (("1 process (launcher -n 1)", p1), ("2 processes", p2)):
        lines.append(f"| {name} | {', '.join(f'{c:.2f}' for c in p['cpu_s_each'])} | {sum(p['cpu_s_each']):.2f} | "
                     f"{max(p['wall_s_each']):.2f} | {sum(p['cpu_s_each']) / sum(p1['cpu_s_each']):.2f} | "
                     f"{max(p['wall_s_each']) / max(p1['wall_s_each']):.2f} |")
    lines.append(f"\nMax abs difference, 2 processes against 1: {out['processes']['max_diff']:.1e}.")
    _common.finish("spin_scale", out, lines, start, args.quick)


if __name__ == "__main__":
    main()
