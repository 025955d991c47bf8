"""Jacobi elliptic functions and Carlson's elliptic integrals in JAX, by fixed-count iterations.

Every function is plain JAX code with a fixed number of iterations (``lax.scan``, no
data-dependent loops): it jits, vmaps and differentiates, and one evaluation costs the same for every
argument. The modulus enters as the pair (k², k'² = 1 − k²) so that a caller who can compute
k'² without cancellation (the free body near its separatrix) passes it exactly.

* ``jacobi(u, k2, kp2)`` -> (sn, cn, dn, am), ``am`` the unwrapped amplitude. u is reduced
  by the half period 2K to [−K, K]; then for k² <= ½ the descending Landen (AGM) recursion
  (DLMF 22.20(ii)), for k² > ½ the ascending Landen transformation (A&S 16.14), which squares
  k'² at every step and ends at k = 1 to beyond double precision, where sn, cn, dn are tanh,
  sech, sech. (The descending recursion alone loses ~1/√k' to an ill-conditioned arcsin as
  k → 1; the ascending one needs k bounded away from 0: each is used where it is exact.)
  Below the smallest normal k'² (the separatrix) K = ∞, u is not reduced, and (sn, cn, dn)
  are the closed forms (tanh u, sech u, sech u).
* ``carlson_rf(x, y, z)``, ``carlson_rj(x, y, z, p)``: Carlson's symmetric integrals by the
  duplication theorem with the fifth-order series (Carlson 1995, Numer. Algorithms 10; DLMF
  19.36(i)). The arguments' spread shrinks 4× per step once they are within a factor ~2 of
  each other, which from a ratio 1e-300 takes ~10 steps: ``CARLSON_STEPS`` covers it.
  K(k) = R_F(0, k'², 1); F(φ|k) = s R_F(c², d², 1) and Π(n; φ|k) = F + (n/3) s³ R_J(c², d²,
  1, 1 − n s²) with (s, c, d) = (sin φ, cos φ, √(1 − k² s²)) for |φ| <= π/2; here n <= 0 (the
  free body's precession), where R_J's arguments satisfy x, y, z <= p.

Square roots of arguments that may vanish go through ``safe_sqrt`` (zero derivative at 0,
never NaN), and the branch not taken is always evaluated on safe values, so gradients stay
finite everywhere.
"""

import jax
import jax.numpy as jnp

DESCENDING_STEPS = 6  # AGM(1, k') for k'² >= ½: converged to round-off after 5 steps
ASCENDING_STEPS = 8  # k'² <= ½ -> below 1e-300 after 7 steps
CARLSON_STEPS = 18  # duplication steps: argument ratios down to 1e-300


def safe_sqrt(x):
    """√x for x >= 0 with a finite (zero) derivative at x = 0 (the double-where idiom)."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def _common(*args):
    """The arguments as arrays of one shape and floating dtype (Python numbers stay weak)."""
    dtype = jnp.result_type(*args)
    return jnp.broadcast_arrays(*(jnp.asarray(a, dtype) for a in args))


def _descending(u, k2, kp2):
    """(sn, cn, dn) by the descending Landen (AGM) recursion, DLMF 22.20(ii): for k² <= ½,
    where the first Landen ratio (1 − k')/(1 + k') <= 0.18 keeps every arcsin well conditioned."""
    u, k2, kp2 = _common(u, k2, kp2)

    def agm(carry, _):
        a, b, c2 = carry
        a_next = (a + b) / 2
        c = c2 / (4 * a_next)  # = (a − b)/2 without cancellation
        return (a_next, jnp.sqrt(a * b), c * c), c / a_next

    # c₀² = k²: no √k, smooth at k = 0
    (a, _, _), ratios = jax.lax.scan(agm, (jnp.ones_like(kp2), jnp.sqrt(kp2), k2), None, length=DESCENDING_STEPS)

    def back(phi, ratio):
        return (phi + jnp.arcsin(ratio * jnp.sin(phi))) / 2, None

    phi, _ = jax.lax.scan(back, 2.0**DESCENDING_STEPS * a * u, ratios, reverse=True)
    cn = jnp.cos(phi)
    return jnp.sin(phi), cn, jnp.sqrt(kp2 + k2 * cn * cn)  # dn² = k'² + k² cn²: no cancellation


def _ascending(u, k2, kp2):
    """(sn, cn, dn) by the ascending Landen (Gauss) transformation, A&S 16.14: for k'² <= ½.
    Each step squares k'² (over 16), so after ``ASCENDING_STEPS`` the modulus is 1 to beyond
    double precision and sn, cn, dn are tanh, sech, sech of the scaled argument."""
    u, k2, kp2 = _common(u, k2, kp2)

    def up(carry, _):
        u, k2, kp2 = carry
        k = jnp.sqrt(k2)
        r = kp2 / ((1 + k) * (1 + k))  # √μ₁ = (1 − k)/(1 + k) without cancellation
        mu = 4 * k / ((1 + k) * (1 + k))
        return (u / (1 + r), mu, r * r), (r, mu)

    (u, _, _), steps = jax.lax.scan(up, (u, k2, kp2), None, length=ASCENDING_STEPS)

    def down(carry, step):
        sn, cn, dn = carry
        r, mu = step
        return ((1 + r) * sn * cn / dn, (1 + r) / mu * (dn * dn - r) / dn, (1 - r) / mu * (dn * dn + r) / dn), None

    sech = _sech(u)
    (sn, cn, dn), _ = jax.lax.scan(down, (jnp.tanh(u), sech, sech), steps, reverse=True)
    return sn, cn, dn


def _sech(u):
    """sech u = 2e^{−|u|} / (1 + e^{−2|u|}): no overflow of cosh for |u| > 710, finite derivative."""
    e = jnp.exp(-jnp.abs(u))
    return 2 * e / (1 + e * e)


def on_separatrix(kp2):
    """k'² below the smallest normal number of its dtype: k = 1 (the separatrix)."""
    return kp2 < jnp.finfo(jnp.result_type(kp2)).tiny


def complete_k(kp2):
    """K(k) = R_F(0, k'², 1) (infinite at k'² = 0)."""
    separatrix = on_separatrix(kp2)
    return jnp.where(separatrix, jnp.inf, carlson_rf(jnp.zeros_like(kp2), jnp.where(separatrix, 0.5, kp2), 1.0))


def jacobi_reduced(u, k2, kp2, big_k=None):
    """(sn, cn, dn)(u_r) and the number of half periods j with u = u_r + 2Kj, u_r ∈ [−K, K]
    (so cn(u_r) >= 0 and am(u) = am(u_r) + jπ): what the integrals along an orbit need.
    ``big_k`` = K(k) when the caller has it (it is a constant of an orbit)."""
    big_k = complete_k(kp2) if big_k is None else big_k
    separatrix = on_separatrix(kp2)
    # K = ∞ on the separatrix: no half periods, u is not reduced (never ∞·0, also in a gradient)
    period = jnp.where(separatrix, 1.0, 2 * big_k)
    turns = jnp.where(separatrix, 0.0, jnp.round(u / period))
    u = u - period * turns
    near_one = kp2 < 0.5
    d = _descending(u, jnp.where(near_one, 0.25, k2), jnp.where(near_one, 0.75, kp2))
    a = _ascending(u, jnp.where(near_one, k2, 0.75), jnp.where(near_one, kp2, 0.25))
    sn, cn, dn = (jnp.where(near_one, x, y) for x, y in zip(a, d))
    sech = _sech(u)  # k = 1: the closed form (tanh, sech, sech), exact whatever k² rounded to
    sn, cn, dn = (jnp.where(separatrix, x, y) for x, y in zip((jnp.tanh(u), sech, sech), (sn, cn, dn)))
    return sn, cn, dn, turns


def jacobi(u, k2, kp2):
    """(sn, cn, dn, am)(u | k) for real u and 0 <= k² <= 1, given k² and k'² = 1 − k²."""
    sn, cn, dn, turns = jacobi_reduced(u, k2, kp2)
    sign = 1 - 2 * jnp.mod(turns, 2)  # sn, cn change sign over a half period
    return sign * sn, sign * cn, dn, jnp.arctan2(sn, cn) + jnp.pi * turns


def partial_pi(n, sn, cn, dn):
    """Π(n; φ | k) for |φ| <= π/2 from (sin φ, cos φ, √(1 − k² sin²φ)), n <= 0."""
    x, y, s2 = cn * cn, dn * dn, sn * sn
    return sn * carlson_rf(x, y, 1.0) + n / 3 * sn * s2 * carlson_rj(x, y, 1.0, 1 - n * s2)


def legendre_integrals(n, sn, cn, dn, kp2):
    """(F(φ|k), Π(n; φ|k), K(k), Π(n|k)) for |φ| <= π/2 given by (sin φ, cos φ, √(1 − k² sin²φ))
    and n <= 0: the incomplete and complete integrals by one R_F and one R_J call."""
    separatrix = on_separatrix(kp2)
    s2 = sn * sn
    x = jnp.stack([cn * cn, jnp.zeros_like(cn)])
    y = jnp.stack([dn * dn, jnp.where(separatrix, 0.5, kp2)])
    rf = carlson_rf(x, y, 1.0)
    rj = carlson_rj(x, y, 1.0, jnp.stack([1 - n * s2, 1 - n * jnp.ones_like(s2)]))
    big_k = jnp.where(separatrix, jnp.inf, rf[1])
    return (sn * rf[0], sn * rf[0] + n / 3 * sn * s2 * rj[0], big_k,
            jnp.where(separatrix, jnp.inf, rf[1] + n / 3 * rj[1]))


def incomplete_pi(n, sn, cn, dn, turns, complete):
    """Π(n; am u | k) = ∫₀^{am u} dθ / ((1 − n sin²θ) √(1 − k² sin²θ)) for n <= 0 from
    ``jacobi_reduced``'s values and ``complete`` = Π(n | k): 2j Π(n | k) + Π(n; am u_r | k)."""
    return partial_pi(n, sn, cn, dn) + jnp.where(turns == 0, 0.0, 2 * turns * jnp.where(turns == 0, 0.0, complete))


def carlson_rf(x, y, z):
    """R_F(x, y, z) = ½ ∫₀^∞ dt / √((t+x)(t+y)(t+z)) for x, y, z >= 0, at most one zero."""
    def duplicate(carry, _):
        x, y, z = carry
        sx, sy, sz = safe_sqrt(x), safe_sqrt(y), safe_sqrt(z)
        lam = sx * sy + sy * sz + sz * sx
        return ((x + lam) / 4, (y + lam) / 4, (z + lam) / 4), None

    (x, y, z), _ = jax.lax.scan(duplicate, tuple(_common(x, y, z)), None, length=CARLSON_STEPS)
    mean = (x + y + z) / 3
    dx, dy = 1 - x / mean, 1 - y / mean
    dz = -(dx + dy)
    e2 = dx * dy - dz * dz
    e3 = dx * dy * dz
    return (1 - e2 / 10 + e3 / 14 + e2 * e2 / 24 - 3 * e2 * e3 / 44) / jnp.sqrt(mean)


def _rc_one(e):
    """R_C(1, 1 + e) = atan(√e)/√e for e >= 0 (a series near 0, where it is 1 − e/3 + …)."""
    small = e < 1e-3
    root = jnp.sqrt(jnp.where(small, 1.0, e))
    return jnp.where(small, 1 - e / 3 + e * e / 5 - e**3 / 7 + e**4 / 9 - e**5 / 11, jnp.arctan(root) / root)


def carlson_rj(x, y, z, p):
    """R_J(x, y, z, p) = (3/2) ∫₀^∞ dt / ((t+p) √((t+x)(t+y)(t+z))) for 0 <= x, y, z <= p
    (the third kind with n <= 0: then every R_C term of the duplication is an arctan)."""
    x, y, z, p = _common(x, y, z, p)
    mean0 = (x + y + z + 2 * p) / 5
    delta = (p - x) * (p - y) * (p - z)

    def duplicate(carry, _):
        x, y, z, p, mean, total, scale = carry  # scale = 4^-m at step m
        sx, sy, sz, sp = safe_sqrt(x), safe_sqrt(y), safe_sqrt(z), jnp.sqrt(p)
        lam = sx * sy + sy * sz + sz * sx
        d = (sp + sx) * (sp + sy) * (sp + sz)
        total = total + scale * _rc_one(delta * scale**3 / (d * d)) / d
        return ((x + lam) / 4, (y + lam) / 4, (z + lam) / 4, (p + lam) / 4, (mean + lam) / 4, total, scale / 4), None

    start = (x, y, z, p, mean0, jnp.zeros_like(x), jnp.ones_like(x))
    (_, _, _, _, mean, total, scale), _ = jax.lax.scan(duplicate, start, None, length=CARLSON_STEPS)
    big_x, big_y, big_z = ((mean0 - a) * scale / mean for a in (x, y, z))
    big_p = -(big_x + big_y + big_z) / 2
    e2 = big_x * big_y + big_x * big_z + big_y * big_z - 3 * big_p * big_p
    e3 = big_x * big_y * big_z + 2 * e2 * big_p + 4 * big_p**3
    e4 = (2 * big_x * big_y * big_z + e2 * big_p + 3 * big_p**3) * big_p
    e5 = big_x * big_y * big_z * big_p * big_p
    series = (1 - 3 * e2 / 14 + e3 / 6 + 9 * e2 * e2 / 88 - 3 * e4 / 22 - 9 * e2 * e3 / 52 + 3 * e5 / 26)
    return scale * series / (mean * jnp.sqrt(mean)) + 6 * total
