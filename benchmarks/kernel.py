"""Which trigonometry should a rotation use? Cost per rotation and accuracy of the kernels.

Candidates for (cos θ, sin θ) inside a run of rotations (Strang, Casimir split: two
rotations per step, the library's own ``_turn_axis``): XLA's ``cos`` + ``sin`` (the
general kernel), the truncated Taylor series accurate to round-off for |θ| <= L only, L =
1/8, 1/4, 1/2, 1 (the kernels of the library before it needed one valid for every angle
under every transformation), and the library's ``so3.cos_sin`` (``half_turn``: a reduction
modulo π and Chebyshev-economized polynomials on |r| <= π/2, any angle). float64 and
float32; one trajectory (B = 1) and a batch of B = 10⁴ states (B, 3). Accuracy: max error
over a dense grid of |θ| <= L (the library's and XLA's: |θ| <= 20) against NumPy's float64
cos/sin, in ulps.

    python benchmarks/kernel.py [--quick]

Writes ``benchmarks/results/kernel.{md,json}``.
"""

import argparse
import functools
import math
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _common import header, interleaved, log, machine_info, ready, write

from jaxsplit.systems import so3


@functools.cache
def truncated_taylor(dtype_name, limit):
    """cos θ and sin θ / θ in θ², each truncated before its first term below eps/4 at |θ| = limit."""
    eps = float(np.finfo(dtype_name).eps)

    def terms(offset):
        out, k = [], 0
        while not out or limit ** (2 * k) / math.factorial(2 * k + offset) > eps / 4:
            out.append((-1) ** k / math.factorial(2 * k + offset))
            k += 1
        return tuple(out)

    return terms(0), terms(1)


def taylor(limit, dtype, coefficients=truncated_taylor):
    cos_c, sin_c = coefficients(np.dtype(dtype).name, limit)

    def cos_sin(theta):
        square = theta * theta
        return so3._horner(cos_c, square), theta * so3._horner(sin_c, square)

    cos_sin.terms = len(cos_c) + len(sin_c)
    return cos_sin


def half_angle(limit, dtype):
    half = taylor(limit / 2, dtype)

    def cos_sin(theta):
        c, s = half(theta / 2)
        return 1 - 2 * s * s, 2 * s * c

    cos_sin.terms = half.terms
    return cos_sin


def general(theta):
    return jnp.cos(theta), jnp.sin(theta)


general.terms = 0


def kernels(dtype):
    out = {"general (XLA cos + sin)": general}
    for limit in (0.125, 0.25, 0.5, 1.0):
        out[f"Taylor, L = {limit:g}"] = taylor(limit, dtype)
    library = lambda theta: so3.cos_sin(theta)
    library.terms = sum(len(c) for c in so3._kernel_constants(np.dtype(dtype).name)[3:])
    out["the library's (half_turn: reduced modulo π, economized; any angle)"] = library
    return out


def strang_run(cos_sin, n):
    """n Strang steps of the Casimir split (axes 0 and 2 turn, shift 1), rotations as in the library."""
    rates = (0.5 - 1.0, 1.5 - 1.0)

    def run(x, h):
        def rotation(y, axis, rate, t):
            theta = rate * t * y[..., axis]
            c, s = cos_sin(theta / 2)  # the half angle, as the library's rotations
            return jax.lax.optimization_barrier(so3._turn_axis(y, axis, c, s))

        def body(y, _):
            return rotation(rotation(y, 0, rates[0], h), 2, rates[1], h), None

        return jax.lax.scan(body, x, length=n)[0]

    return jax.jit(run)


def accuracy(cos_sin, limit, dtype):
    theta = jnp.linspace(-limit, limit, 200_001, dtype=dtype)
    c, s = (np.asarray(a, np.float64) for a in cos_sin(theta))
    exact = np.asarray(theta, np.float64)
    eps = float(jnp.finfo(dtype).eps)
    return {"cos_ulps": float(np.max(np.abs(c - np.cos(exact))) / eps),
            "sin_ulps": float(np.max(np.abs(s - np.sin(exact))) / eps),
            "circle_ulps": float(np.max(np.abs(c * c + s * s - 1)) / eps)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    quick = parser.parse_args(argv).quick
    command = "python benchmarks/kernel.py" + (" --quick" if quick else "")
    out = machine_info(command)
    start = time.perf_counter()
    repeats = 3 if quick else 7
    layouts = {"B = 1": (1, 20_000 if quick else 200_000), "B = 10⁴": (10_000, 20 if quick else 200)}
    rng = np.random.default_rng(0)
    rows = []
    for dtype in (jnp.float64, jnp.float32):
        for layout, (b, n) in layouts.items():
            x = rng.standard_normal((b, 3)) if b > 1 else rng.standard_normal(3)
            x = jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True), dtype)
            h = jnp.asarray(0.4, dtype)
            cases = {}
            for name, cs in kernels(dtype).items():
                fn = strang_run(cs, n)
                jax.block_until_ready(fn(x, h))
                cases[name] = ready(fn, x, h)
            log(f"{np.dtype(dtype).name} {layout}: timing {len(cases)} kernels")
            times = interleaved(cases, repeats)
            base = "general (XLA cos + sin)"
            for name, cs in kernels(dtype).items():
                limit = float(name.split("L = ")[1]) if "L = " in name else 20.0
                ns = statistics.median(times[name]) / (2 * n * b) * 1e9
                ratio = statistics.median(a / g for a, g in zip(times[name], times[base]))
                rows.append({"dtype": np.dtype(dtype).name, "layout": layout, "kernel": name, "terms": cs.terms,
                             "ns_per_rotation": ns, "time_vs_general": ratio, **accuracy(cs, limit, dtype)})
    out["rows"] = rows
    lines = header(out, "Rotation kernels (`benchmarks/kernel.py`)")
    lines += [("Time per rotation inside a Strang run (median of interleaved rounds) and its ratio to the general "
              "kernel in the same round; accuracy over |θ| <= L (general and the library's: over |θ| <= 20) in units of the dtype's "
              "eps."), "",
              ("| dtype | layout | kernel | polynomial terms | ns / rotation | × general | cos error | sin error "
              "| cos²+sin²−1 |"), "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['dtype']} | {r['layout']} | {r['kernel']} | {r['terms'] or '—'} | {r['ns_per_rotation']:.3g} "
                     f"| {r['time_vs_general']:.2f} | {r['cos_ulps']:.2f} | {r['sin_ulps']:.2f} | "
                     f"{r['circle_ulps']:.2f} |")
    out["wall_s"] = time.perf_counter() - start
    lines += ["", f"Total wall time {out['wall_s']:.0f} s. Library: `so3.cos_sin` (any angle)."]
    write("kernel", quick, out, lines)


if __name__ == "__main__":
    main()
