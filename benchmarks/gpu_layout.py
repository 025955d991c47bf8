"""Which rotation form is fastest in jaxsplit's loops on an accelerator, for the free-body batch
(10⁶ bodies, Strang, 2,000 steps): the default, the select form (the CPU's) and the stack form
(``core._loops.select_form``), each as a direct call and under jit(vmap), beside the
hand-fused loop of ``throughput.py``; wall time, best of 3.

    python benchmarks/gpu_layout.py [--quick] [OUT_DIR]   # prints a table; writes the direct programs' HLO to OUT_DIR
"""

import contextlib
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import throughput
from _common import interleaved

import jaxsplit
from jaxsplit.core._loops import select_form

B, N = (10**4, 200) if "--quick" in sys.argv else (10**6, 2000)


def best(fn, rounds=3):
    """Wall seconds of ``fn()``, the best of ``rounds`` after a warm-up call."""
    fn()
    return min(interleaved({"run": fn}, rounds)["run"])


def main():
    folders = [a for a in sys.argv[1:] if not a.startswith("--")]
    out = Path(folders[0]) if folders else None
    m = jnp.asarray(throughput.states(B))
    step = jaxsplit.splitting(jaxsplit.RigidBody(jnp.asarray(throughput.INERTIA), allow_nonphysical=True), "strang",
                              "casimir", shift=1)
    fused = throughput.fused_run(N, throughput.polynomial)
    rows = {"hand-fused JAX, polynomial": best(lambda: fused(m, throughput.H).block_until_ready())}
    for form in ("default", "select", "stack"):
        jax.clear_caches()  # the form is read while tracing
        with select_form(form == "select") if form != "default" else contextlib.nullcontext():
            direct = jax.jit(lambda x: jaxsplit.integrate(step, x, throughput.H, N).final)
            mapped = jax.jit(jax.vmap(lambda x: jaxsplit.integrate(step, x, throughput.H, N).final))
            rows[f"direct, {form} form"] = best(lambda f=direct: f(m).block_until_ready())
            rows[f"jit(vmap), {form} form"] = best(lambda f=mapped: f(m).block_until_ready())
            if out is not None:
                (out / f"hlo-direct-{form}.txt").write_text(direct.lower(m).compile().as_text())
    print(f"{jax.devices()[0]}; B = {B}, {N} steps; M body-steps/s (hand-fused / it)")
    for k, t in rows.items():
        print(f"| {k} | {B * N / t / 1e6:.4g} | {t / rows['hand-fused JAX, polynomial']:.2f}x |")


if __name__ == "__main__":
    main()
