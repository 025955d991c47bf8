"""How many body-steps per second does a batch reach? Strang on the Casimir split against
NumPy and hand-fused JAX loops, side by side.

Standard body I = (2, 1, 2/3), shift axis 1 (two rotations per step), random unit states,
h = 0.01, float64, B = 1, 10², 10⁴, 10⁵ bodies. Contenders (the same rotations in the same
order, checked to agree to round-off):

* jaxsplit: ``integrate(step, states, h, n)`` on the (B, 3) array as a user writes it (the
  run picks the polynomial kernel and lays the batch out components-first);
* jaxsplit with the general kernel and the (B, 3) layout (the same call under ``jax.jit``,
  where values are traced: the library before this work);
* hand-fused JAX: one ``lax.fori_loop`` over the three component arrays, the rotations
  written inline, with XLA's cos/sin, and with the library's polynomial;
* NumPy: the same algebra vectorised over the batch in a Python loop (``np.cos``/``np.sin``).

Every JAX contender is compiled with jaxsplit's compiler options (``jaxsplit.compiler_options()``,
512-bit vectors), as ``integrate``'s own programs are: the same code generation for all.

    python benchmarks/throughput.py [--quick]

Writes ``benchmarks/results/throughput.{md,json}``.
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import finish, header, interleaved, log, machine_info, paired_ratio, ready

import jaxsplit
from jaxsplit.systems import so3

INERTIA = np.asarray(jaxsplit.STANDARD_CASE.inertia)
C0, C2 = 1 / INERTIA[0] - 1 / INERTIA[1], 1 / INERTIA[2] - 1 / INERTIA[1]  # Casimir split, shift 1
H = 0.01
BATCHES = (1, 100, 10_000, 100_000)
ACCELERATOR_BATCHES = (10**6, 10**7)  # on a GPU: batches that fill the chip
# On a GPU every step of a loop is at least one kernel launch (~10 µs): a run of 2·10⁶ steps on
# one body would take minutes and measure only launches, so the steps are capped there
ACCELERATOR_MAX_STEPS = 2000


def states(b: int):
    m = np.random.default_rng(0).standard_normal((b, 3))
    return m / np.linalg.norm(m, axis=1, keepdims=True)


def strang_step(x, y, z, h, cos_sin):
    """The merged Strang steps between the first and last half-steps: axis 2 by h, then axis 0 by h."""
    c, s = cos_sin(C2 * h * z)
    x, y = c * x + s * y, -s * x + c * y
    c, s = cos_sin(C0 * h * x)
    return x, c * y + s * z, -s * y + c * z


def numpy_run(m, n):
    x, y, z = (np.array(m[:, k]) for k in range(3))
    c, s = np.cos(C0 * H / 2 * x), np.sin(C0 * H / 2 * x)
    y, z = c * y + s * z, -s * y + c * z
    for _ in range(n - 1):
        x, y, z = strang_step(x, y, z, H, lambda a: (np.cos(a), np.sin(a)))
    c, s = np.cos(C2 * H * z), np.sin(C2 * H * z)
    x, y = c * x + s * y, -s * x + c * y
    c, s = np.cos(C0 * H / 2 * x), np.sin(C0 * H / 2 * x)
    return np.stack([x, y * c + s * z, -s * y + c * z], axis=-1)


def fused_run(n, cos_sin):
    def run(m, h):
        x, y, z = m[:, 0], m[:, 1], m[:, 2]
        c, s = cos_sin(C0 * h / 2 * x)
        y, z = c * y + s * z, -s * y + c * z
        x, y, z = jax.lax.fori_loop(0, n - 1, lambda _, v: strang_step(*v, h, cos_sin), (x, y, z))
        c, s = cos_sin(C2 * h * z)
        x, y = c * x + s * y, -s * x + c * y
        c, s = cos_sin(C0 * h / 2 * x)
        return jnp.stack([x, c * y + s * z, -s * y + c * z], axis=-1)

    return jax.jit(run, compiler_options=OPTIONS)


OPTIONS = jaxsplit.compiler_options() or None


def polynomial(angle):
    """The library's kernel (``so3.cos_sin``: reduction modulo π and economized polynomials)."""
    return so3.cos_sin(angle)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/throughput.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    total, repeats = (2 * 10**5, 3) if quick else (2 * 10**6, 7)
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.asarray(INERTIA), allow_nonphysical=True), "strang", "casimir", shift=1)
    accelerator = jax.default_backend() != "cpu"
    batches = BATCHES + (ACCELERATOR_BATCHES if accelerator else ())
    rows = []
    for b in batches:
        n = max(20, min(total // b, ACCELERATOR_MAX_STEPS) if accelerator else total // b)
        m = jnp.asarray(states(b))
        n_numpy = max(20, n // 10) if b < 1000 else n if b <= 100_000 else 4  # NumPy's rate is flat in n there
        general = jax.jit(lambda x, n=n: jaxsplit.integrate(step, x, H, n).final)
        mapped = jax.jit(jax.vmap(lambda x, n=n: jaxsplit.integrate(step, x, H, n).final))
        cases = {
            "jaxsplit": lambda m=m, n=n: jaxsplit.integrate(step, m, H, n).final.block_until_ready(),
            "jaxsplit, jit(vmap)": ready(mapped, m),
            "hand-fused JAX, XLA cos/sin": ready(fused_run(n, lambda a: (jnp.cos(a), jnp.sin(a))), m, H),
            "hand-fused JAX, polynomial": ready(fused_run(n, polynomial), m, H),
            "NumPy, vectorised loop": lambda m=m, n=n_numpy: numpy_run(np.asarray(m), n),
        }
        steps = {name: (n_numpy if name.startswith("NumPy") else n) for name in cases}
        reference = np.asarray(general(m))
        for name, fn in cases.items():
            fn()
        for name in ("jaxsplit", "hand-fused JAX, polynomial"):
            got = np.asarray(jaxsplit.integrate(step, m, H, n).final) if name == "jaxsplit" else np.asarray(
                fused_run(n, polynomial)(m, H))
            assert np.max(np.abs(got - reference)) < 1e-9, (name, np.max(np.abs(got - reference)))
        assert np.max(np.abs(numpy_run(np.asarray(m), n) - reference)) < 1e-9
        log(f"B = {b}: timing")
        times = interleaved(cases, repeats)
        per = {name: [t / (steps[name] * b) for t in ts] for name, ts in times.items()}
        for name in cases:
            rows.append({"B": b, "method": name, "steps": steps[name],
                         "body_steps_per_s": 1 / statistics.median(per[name]),
                         "speedup_vs_numpy": paired_ratio(per, "NumPy, vectorised loop", name)})
    out["rows"] = rows
    lines = header(out, "Batch throughput (`benchmarks/throughput.py`)")
    lines += [("Strang, Casimir split (2 rotations per step), float64, h = 0.01. Million body-steps per second "
              "(median of interleaved rounds) and, in brackets, the speed-up over the NumPy loop (median of the "
              "per-round ratios)."), "",
              "| method | " + " | ".join(f"B = {b:,}" for b in batches) + " |", "|---|" + "---|" * len(batches)]
    for name in dict.fromkeys(r["method"] for r in rows):
        cells = [next(f"{r['body_steps_per_s'] / 1e6:.3g} ({r['speedup_vs_numpy']:.2g}×)" for r in rows
                      if r["B"] == b and r["method"] == name) for b in batches]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    finish("throughput", out, lines, start, quick)


if __name__ == "__main__":
    main()
