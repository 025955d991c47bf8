"""The spin-lattice algebra of ``spins.py``, written out by hand: the bond splitting of the
periodic simple-cubic Heisenberg lattice as a plain vectorised NumPy loop and as a hand-fused
JAX loop (the speed target for jaxsplit's ``spin_lattice`` system).

Conventions (jaxsplit's): H = −J Σ_bonds S_i·S_j and Ṡ_i = ∇_i H × S_i. A bond's flow keeps
s = S_i + S_j and turns both spins about s: ȧ = −J s × a, so a(t) = R_s(−J|s|t) a and
b(t) = s − a(t). With θ = J|s|t:

    a' = cos θ · a − (sin θ/|s|) · s × a + ((1 − cos θ)/|s|²) (s·a) · s,

and sin θ/|s| = Jt · sin θ/θ, (1 − cos θ)/|s|² = (Jt)²/2 · (sin(θ/2)/(θ/2))² are functions
of θ² alone: the JAX loop evaluates cos(θ/2) and sin(θ/2)/(θ/2) as Taylor polynomials in
(θ/2)², truncated for the run's bound on |θ| (no square root, division or range reduction);
the NumPy loop calls ``np.cos`` and ``np.sinc``.

Colours: the bonds of a periodic L × L × L lattice (L even) fall into six perfect matchings,
(axis, parity): the bonds along ``axis`` from coordinate 2k + parity to 2k + parity + 1
(mod L). A colour is one exact flow (its bonds share no spin). Strang over the colours is the
palindrome c1(h/2) … c5(h/2) c6(h) c5(h/2) … c1(h/2); consecutive steps share c1, so a run of
n steps applies 10n + 1 colour flows (``merged_run``). A composition of Strang steps with
weights w (triple jump, ...) is the same word with each weight's palindrome in turn.

State layout: components first, (3, L, L, L), C order; site (i, j, l) is site i·L² + j·L + l
of jaxsplit's (N, 3) state. A colour's bond pairs are a reshape of its axis into (L/2, 2)
(parity 1 after a roll by one site): no gathers, no scatters.
"""

import math

import numpy as np

COLOURS = tuple((axis, parity) for axis in range(3) for parity in range(2))


def strang_word(weights=(1.0,)):
    """One step as a word of (colour, fraction of h): each weight's Strang palindrome in turn,
    adjacent flows of one colour merged."""
    word = []
    for w in weights:
        half = [(c, w / 2) for c in COLOURS[:-1]]
        for colour, t in half + [(COLOURS[-1], w)] + half[::-1]:
            if word and word[-1][0] == colour:
                word[-1] = (colour, word[-1][1] + t)
            else:
                word.append((colour, t))
    return tuple(word)


def merged_run(word, n):
    """(prefix, loop body, suffix) words of n steps: the last flow of a step and the first of
    the next are one colour, so the loop runs them as one flow."""
    (first, t0), (last, t1) = word[0], word[-1]
    if n < 1 or first != last:
        raise ValueError(f"merged_run needs n >= 1 and a word that starts and ends with one colour, got n={n}")
    return word[:1], word[1:-1] + ((first, t0 + t1),), word[1:]


def yoshida_weights(order: int):
    """Strang weights of Yoshida's triple-jump composition of the given even order (2, 4, 6, 8)."""
    weights = (1.0,)
    for p in range(2, order, 2):
        w1 = 1 / (2 - 2 ** (1 / (p + 1)))
        w0 = 1 - 2 * w1
        weights = tuple(w * x for x in (w1, w0, w1) for w in weights)
    return weights


def energy(state, exchange):
    """H = −J Σ_bonds S_i·S_j of a (..., L, L, L) components-first (3, L, L, L) state."""
    s = np.asarray(state)
    return -exchange * sum(float(np.sum(s * np.roll(s, -1, axis))) for axis in (1, 2, 3))


# --- NumPy -----------------------------------------------------------------------------------


def _numpy_colour(s, colour, jt):
    axis, parity = colour
    ax = axis + 1
    if parity:
        s = np.roll(s, -1, ax)
    size = s.shape[ax]
    pairs = s.reshape(s.shape[:ax] + (size // 2, 2) + s.shape[ax + 1:])
    a, b = np.take(pairs, 0, axis=ax + 1), np.take(pairs, 1, axis=ax + 1)
    total = a + b
    theta = jt * np.sqrt(np.sum(total * total, axis=0))
    sin_s = jt * np.sinc(theta / np.pi)                      # sin θ / |s|
    one_minus_cos = 0.5 * jt * jt * np.sinc(theta / (2 * np.pi)) ** 2  # (1 − cos θ)/|s|²
    a2 = (np.cos(theta) * a - sin_s * np.cross(total, a, axis=0)
          + one_minus_cos * np.sum(total * a, axis=0) * total)
    out = np.stack([a2, total - a2], axis=ax + 1).reshape(s.shape)
    return np.roll(out, 1, ax) if parity else out


def numpy_run(state, h, n, exchange, weights=(1.0,)):
    """n steps of the composition on a (3, L, L, L) float64 array, a Python loop of vectorised
    colour flows (the same word and merging as the JAX loop)."""
    prefix, body, suffix = merged_run(strang_word(weights), n)
    s = np.array(state, dtype=np.float64)
    for colour, t in prefix:
        s = _numpy_colour(s, colour, exchange * h * t)
    for _ in range(n - 1):
        for colour, t in body:
            s = _numpy_colour(s, colour, exchange * h * t)
    for colour, t in suffix:
        s = _numpy_colour(s, colour, exchange * h * t)
    return s


# --- hand-fused JAX --------------------------------------------------------------------------


def half_angle_terms(bound: float) -> int:
    """Terms beyond the first of the Taylor series of cos x and sin x / x in x² for |x| <= bound
    (x = θ/2), the first neglected term below 2⁻⁵⁶ (a quarter of float64's epsilon)."""
    k = 1
    while bound ** (2 * k + 2) / math.factorial(2 * k + 2) > 2.0 ** -56:
        k += 1
    return k


def _half_polynomials(u, terms):
    """cos(x) and sin(x)/x for u = x², Horner."""
    c = sinc = 0.0
    for k in reversed(range(terms + 1)):
        sign = -1.0
        c = c * sign * u + 1.0 / math.factorial(2 * k)
        sinc = sinc * sign * u + 1.0 / math.factorial(2 * k + 1)
    return c, sinc


def _fused_pair(a, b, jt, terms):
    sx, sy, sz = a[0] + b[0], a[1] + b[1], a[2] + b[2]
    s2 = sx * sx + sy * sy + sz * sz
    c_half, sinc_half = _half_polynomials(0.25 * jt * jt * s2, terms)
    sin_s = -jt * sinc_half * c_half         # −sin θ / |s|
    v = 0.5 * jt * jt * sinc_half * sinc_half  # (1 − cos θ)/|s|²
    c = 1.0 - v * s2
    w = v * (sx * a[0] + sy * a[1] + sz * a[2])
    ax = c * a[0] + sin_s * (sy * a[2] - sz * a[1]) + w * sx
    ay = c * a[1] + sin_s * (sz * a[0] - sx * a[2]) + w * sy
    az = c * a[2] + sin_s * (sx * a[1] - sy * a[0]) + w * sz
    return (ax, ay, az), (sx - ax, sy - ay, sz - az)


def _fused_colour(s, colour, jt, terms):
    import jax.numpy as jnp

    axis, parity = colour
    ax = axis + 1
    if parity:
        s = jnp.roll(s, -1, ax)
    size = s.shape[ax]
    pairs = s.reshape(s.shape[:ax] + (size // 2, 2) + s.shape[ax + 1:])
    a, b = jnp.take(pairs, 0, axis=ax + 1), jnp.take(pairs, 1, axis=ax + 1)
    a2, b2 = _fused_pair(tuple(a), tuple(b), jt, terms)
    out = jnp.stack([jnp.stack(a2), jnp.stack(b2)], axis=ax + 1).reshape(s.shape)
    return jnp.roll(out, 1, ax) if parity else out


def fused_run(exchange, h_bound, spin_length=1.0, weights=(1.0,), compiler_options=None):
    """A jitted ``run(state, h, n)``, (3, L, L, L) -> (3, L, L, L): n steps of the
    composition in one ``lax.fori_loop`` (h and n traced: one compilation for every step size
    and count), each colour flow written inline; the polynomial truncated for |h| <= h_bound
    (|θ/2| <= |J|·max|S|·|h|·(largest fraction of h in one flow), max|S| = ``spin_length``).
    Strang runs the merged word (10 flows per step); a composition of several Strang steps
    loops over its weights (11 flows per weight), which compiles one palindrome, not all."""
    import jax
    import jax.numpy as jnp

    if len(weights) == 1:
        word = strang_word(weights)
        largest = max(abs(t) for _, t in merged_run(word, 2)[1])
    else:
        word = strang_word((1.0,))
        largest = max(abs(w) for w in weights)
    terms = half_angle_terms(abs(exchange) * spin_length * h_bound * largest)

    def flows(s, word, h):
        for colour, t in word:
            s = _fused_colour(s, colour, exchange * h * t, terms)
        return s

    def strang(s, h, n):
        prefix, body, suffix = merged_run(word, 1)[0], merged_run(word, 2)[1], word[1:]
        s = flows(s, prefix, h)
        s = jax.lax.fori_loop(0, n - 1, lambda _, s: flows(s, body, h), s)
        return flows(s, suffix, h)

    def composition(s, h, n):
        w = jnp.asarray(weights, dtype=s.dtype)
        step = lambda _, s: jax.lax.fori_loop(0, len(weights), lambda k, s: flows(s, word, h * w[k]), s)
        return jax.lax.fori_loop(0, n, step, s)

    return jax.jit(strang if len(weights) == 1 else composition, compiler_options=compiler_options)
