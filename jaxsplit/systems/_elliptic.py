"""Jacobi elliptic functions and Carlson's elliptic integrals in JAX, by fixed-count iterations.

Every function is plain ``jnp`` code with a fixed number of iterations (no data-dependent
loops): it jits, vmaps and differentiates, and one evaluation costs the same for every
argument. The modulus enters as the pair (k², k'² = 1 − k²) so that a caller who can compute
k'² without cancellation (the free body near its separatrix) passes it exactly.

* ``jacobi(u, k2, kp2)`` -> (sn, cn, dn, am), ``am`` the unwrapped amplitude. u is reduced
  by the half period 2K to [−K, K]; then for k² <= ½ the descending Landen (AGM) recursion
  (DLMF 22.20(ii)), for k² > ½ the ascending Landen transformation (A&S 16.14), which squares
  k'² at every step and ends at k = 1 to beyond double precision, where sn, cn, dn are tanh,
  sech, sech. (The descending recursion alone loses ~1/√k' to an ill-conditioned arcsin as
  k → 1; the ascending one needs k bounded away from 0: each is used where it is exact.)
  Below the smallest normal k'² (the separatrix) K = ∞ and the k = 1 functions are exact.
* ``carlson_rf(x, y, z)``, ``carlson_rj(x, y, z, p)``: Carlson's symmetric integrals by the
  duplication theorem with the fifth-order series (Carlson 1995, Numer. Algorithms 10; DLMF
  19.36(i)). The arguments' spread shrinks 4× per step once they are within a factor ~2 of
  each other, which from a ratio 1e-300 takes ~10 steps: ``CARLSON_STEPS`` covers it.
  K(k) = R_F(0, k'², 1); F(φ|k) = s R_F(c², d², 1) and Π(n; φ|k) = F + (n/3) s³ R_J(c², d²,
  1, 1 − n s²) with (s, c, d) = (sin φ, cos φ, √(1 − k² s²)) for |φ| <= π/2.

Square roots of arguments that may vanish go through ``safe_sqrt`` (zero derivative at 0,
never NaN), and the branch not taken is always evaluated on safe values, so gradients stay
finite everywhere.
"""

import jax.numpy as jnp

DESCENDING_STEPS = 6  # AGM(1, k') for k'² >= ½: converged to round-off after 5 steps
ASCENDING_STEPS = 8  # k'² <= ½ -> below 1e-300 after 7 steps
CARLSON_STEPS = 18  # duplication steps: argument ratios down to 1e-300


def safe_sqrt(x):
    """√x for x >= 0 with a finite (zero) derivative at x = 0 (the double-where idiom)."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def _descending(u, k2, kp2):
    """(sn, cn, dn) by the descending Landen (AGM) recursion, DLMF 22.20(ii): for k² <= ½,
    where the first Landen ratio (1 − k')/(1 + k') <= 0.18 keeps every arcsin well conditioned."""
    a, b, c2 = jnp.ones_like(kp2), jnp.sqrt(kp2), k2  # c₀² = k²: no √k, smooth at k = 0
    ratios = []
    for _ in range(DESCENDING_STEPS):
        a_next = (a + b) / 2
        c = c2 / (4 * a_next)  # = (a − b)/2 without cancellation
        c2 = c * c
        b = jnp.sqrt(a * b)
        a = a_next
        ratios.append(c / a)
    phi = 2.0**DESCENDING_STEPS * a * u
    for ratio in reversed(ratios):
        phi = (phi + jnp.arcsin(ratio * jnp.sin(phi))) / 2
    cn = jnp.cos(phi)
    return jnp.sin(phi), cn, jnp.sqrt(kp2 + k2 * cn * cn)  # dn² = k'² + k² cn²: no cancellation


def _ascending(u, k2, kp2):
    """(sn, cn, dn) by the ascending Landen (Gauss) transformation, A&S 16.14: for k'² <= ½.
    Each step squares k'² (over 16), so after ``ASCENDING_STEPS`` the modulus is 1 to beyond
    double precision and sn, cn, dn are tanh, sech, sech of the scaled argument."""
    steps = []
    for _ in range(ASCENDING_STEPS):
        k = jnp.sqrt(k2)
        r = kp2 / ((1 + k) * (1 + k))  # √μ₁ = (1 − k)/(1 + k) without cancellation
        k2, kp2 = 4 * k / ((1 + k) * (1 + k)), r * r
        u = u / (1 + r)
        steps.append((r, k2))
    sn, cn = jnp.tanh(u), 1 / jnp.cosh(u)
    dn = cn
    for r, mu in reversed(steps):
        sn, cn, dn = ((1 + r) * sn * cn / dn, (1 + r) / mu * (dn * dn - r) / dn,
                      (1 - r) / mu * (dn * dn + r) / dn)
    return sn, cn, dn


def on_separatrix(kp2):
    """k'² below the smallest normal number of its dtype: k = 1 (the separatrix)."""
    return kp2 < jnp.finfo(jnp.result_type(kp2)).tiny


def complete_k(kp2):
    """K(k) = R_F(0, k'², 1) (infinite at k'² = 0)."""
    separatrix = on_separatrix(kp2)
    return jnp.where(separatrix, jnp.inf, carlson_rf(jnp.zeros_like(kp2), jnp.where(separatrix, 0.5, kp2), 1.0))


def jacobi_reduced(u, k2, kp2):
    """(sn, cn, dn)(u_r) and the number of half periods j with u = u_r + 2Kj, u_r ∈ [−K, K]
    (so cn(u_r) >= 0 and am(u) = am(u_r) + jπ): what the integrals along an orbit need."""
    big_k = complete_k(kp2)
    turns = jnp.round(u / (2 * big_k))
    u = u - 2 * big_k * jnp.where(turns == 0, 0.0, turns)  # K = ∞ at the separatrix: no reduction
    near_one = kp2 < 0.5
    d = _descending(u, jnp.where(near_one, 0.25, k2), jnp.where(near_one, 0.75, kp2))
    a = _ascending(u, jnp.where(near_one, k2, 0.75), jnp.where(near_one, kp2, 0.25))
    sn, cn, dn = (jnp.where(near_one, x, y) for x, y in zip(a, d))
    return sn, cn, dn, turns


def jacobi(u, k2, kp2):
    """(sn, cn, dn, am)(u | k) for real u and 0 <= k² <= 1, given k² and k'² = 1 − k²."""
    sn, cn, dn, turns = jacobi_reduced(u, k2, kp2)
    sign = 1 - 2 * jnp.mod(turns, 2)  # sn, cn change sign over a half period
    return sign * sn, sign * cn, dn, jnp.arctan2(sn, cn) + jnp.pi * turns


def incomplete_pi(n, sn, cn, dn, turns, k2, kp2):
    """Π(n; am u | k) = ∫₀^{am u} dθ / ((1 − n sin²θ) √(1 − k² sin²θ)) for n <= 0, from
    ``jacobi_reduced``'s values: 2j Π(n | k) + Π(n; am u_r | k)."""
    x, y = cn * cn, dn * dn
    s2 = sn * sn
    partial = sn * carlson_rf(x, y, 1.0) + n / 3 * sn * s2 * carlson_rj(x, y, 1.0, 1 - n * s2)
    separatrix = on_separatrix(kp2)  # j = 0 there, and the complete integral is infinite
    kp2 = jnp.where(separatrix, 0.5, kp2)
    zero = jnp.zeros_like(kp2)
    complete = carlson_rf(zero, kp2, 1.0) + n / 3 * carlson_rj(zero, kp2, 1.0, 1 - n)
    return partial + jnp.where(turns == 0, 0.0, 2 * turns * complete)


def carlson_rf(x, y, z):
    """R_F(x, y, z) = ½ ∫₀^∞ dt / √((t+x)(t+y)(t+z)) for x, y, z >= 0, at most one zero."""
    for _ in range(CARLSON_STEPS):
        sx, sy, sz = safe_sqrt(x), safe_sqrt(y), safe_sqrt(z)
        lam = sx * sy + sy * sz + sz * sx
        x, y, z = (x + lam) / 4, (y + lam) / 4, (z + lam) / 4
    mean = (x + y + z) / 3
    dx, dy = 1 - x / mean, 1 - y / mean
    dz = -(dx + dy)
    e2 = dx * dy - dz * dz
    e3 = dx * dy * dz
    return (1 - e2 / 10 + e3 / 14 + e2 * e2 / 24 - 3 * e2 * e3 / 44) / jnp.sqrt(mean)


def _rc_one(e):
    """R_C(1, 1 + e) (e > −1): atan(√e)/√e, atanh(√−e)/√−e, a series near e = 0."""
    small = jnp.abs(e) < 1e-3
    safe = jnp.where(small, 1.0, e)
    root = safe_sqrt(jnp.abs(safe))
    big = jnp.where(safe > 0, jnp.arctan(root), jnp.arctanh(jnp.where(safe > 0, 0.5, root))) / root
    series = 1 - e / 3 + e * e / 5 - e**3 / 7 + e**4 / 9 - e**5 / 11
    return jnp.where(small, series, big)


def carlson_rj(x, y, z, p):
    """R_J(x, y, z, p) = (3/2) ∫₀^∞ dt / ((t+p) √((t+x)(t+y)(t+z))) for x, y, z >= 0, p > 0."""
    mean0 = (x + y + z + 2 * p) / 5
    delta = (p - x) * (p - y) * (p - z)
    total = jnp.zeros_like(mean0)
    mean = mean0
    scale = 1.0
    x0, y0, z0, p0 = x, y, z, p
    for m in range(CARLSON_STEPS):
        sx, sy, sz, sp = safe_sqrt(x), safe_sqrt(y), safe_sqrt(z), jnp.sqrt(p)
        lam = sx * sy + sy * sz + sz * sx
        d = (sp + sx) * (sp + sy) * (sp + sz)
        e = delta * 4.0 ** (-3 * m) / (d * d)
        total = total + scale * _rc_one(e) / d
        scale /= 4
        x, y, z, p = (x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (p + lam) / 4
        mean = (mean + lam) / 4
    big_x = (mean0 - x0) * scale / mean
    big_y = (mean0 - y0) * scale / mean
    big_z = (mean0 - z0) * scale / mean
    big_p = -(big_x + big_y + big_z) / 2
    e2 = big_x * big_y + big_x * big_z + big_y * big_z - 3 * big_p * big_p
    e3 = big_x * big_y * big_z + 2 * e2 * big_p + 4 * big_p**3
    e4 = (2 * big_x * big_y * big_z + e2 * big_p + 3 * big_p**3) * big_p
    e5 = big_x * big_y * big_z * big_p * big_p
    series = (1 - 3 * e2 / 14 + e3 / 6 + 9 * e2 * e2 / 88 - 3 * e4 / 22 - 9 * e2 * e3 / 52 + 3 * e5 / 26)
    return scale * series / (mean * jnp.sqrt(mean)) + 6 * total
