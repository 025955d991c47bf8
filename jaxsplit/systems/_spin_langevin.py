"""Spins at temperature T: stochastic Landau–Lifshitz–Gilbert (sLLG) dynamics by a splitting in
which every piece is a rotation of each spin, so every |S_i| is kept to round-off.

The equation (Stratonovich), in the convention of ``_spin_lattice`` (Ṡ_i = ∂H/∂S_i × S_i):

    dS_i = [(∂H/∂S_i − λ S_i × ∂H/∂S_i) dt + dW_i] × S_i,   ⟨dW_i^a dW_j^b⟩ = 2λT δ_ij δ_ab dt,

the precession of ``spin_lattice``, the Landau–Lifshitz damping λ (ꟷλ(S × g) × S = −λ s² g_⊥,
a gradient descent of H on each sphere of radius s) and a random rotation. Its Fokker–Planck
equation on (S²)ᴺ has the Boltzmann density exp(−H/T) as stationary solution exactly when the
noise strength is 2λT (fluctuation–dissipation; the precession keeps H and the uniform measure,
so it keeps every f(H)). Units: k_B = 1, T in the units of H; λ dimensionless (per unit spin
length squared, s² λ is the rate of the damping of a spin of length s).

The step (``Langevin``), a symmetric composition in the manner of Leimkuhler and Matthews'
BAOAB (Appl. Math. Res. Express 2013, 34; the dissipative–stochastic part in the middle):

    H(h/2) ∘ O(h) ∘ H(h/2)

* H: one step of a registry scheme on the exact bond and site flows (split ``"bonds"`` of
  ``spin_lattice``): a Poisson map.
* O(h): the damping and the noise, per sublattice (``vertex_colours``: no bond joins two sites
  of a colour, so the exchange and Zeeman field g_i = ∂H/∂S_i on a colour's sites is frozen
  while they move), swept forward over the colours with h/2 and back with h/2 (a ``lax.scan``
  over the visits: one compiled visit); on colour c for a time τ:
  damping(τ/2) · noise(τ) · damping(τ/2), with the anisotropy's damping (a
  site-local piece) before and after the sweep. Each is an exact solution:

  - damping in a frozen field B = −g: S turns about S × B towards B, the angle θ to B obeys
    θ' = −λ s |B| sin θ, so tan(θ/2) ← tan(θ/2) e^{−λ s |B| τ} (the single-spin solution used
    by Mentink, Tretyakov, Fasolino, Katsnelson, Rasing, J. Phys.: Condens. Matter 22 (2010)
    176001, whose splitting of the sLLG into per-spin exact rotations this follows);
  - uniaxial anisotropy −K (n·S)²: S turns in the plane of S and n, tan φ ← tan φ e^{−2λKs²τ}
    (φ the angle to n);
  - noise: a rotation of each spin by a Gaussian angle vector of variance 2λTτ per component
    (the Stratonovich increment; its generator is λT·Δ_S² to O(τ²)).

Every piece is a rotation of each spin (``turn``): |S_i| is exact at every step. The damping
pieces and H are exact flows; the Gaussian rotation matches spherical Brownian motion to
first order in τ, which with the frozen-field sweep makes the stationary averages biased by a
term that vanishes with h (measured in ``benchmarks/spin_thermal.py``: choose h so that it is
below the statistical error).

The state is a pair ``(spins, key)``: the spins ((N, 3), the lattice's shape + (3,), or a
batch (B, N, 3)) and a raw ``jax.random.PRNGKey`` (uint32 (2,)), split once per step, so a
run is reproducible from its key and ``integrate`` saves the key with the spins. A batch of
spins with one key draws independent noise for every replica; ``jax.vmap`` over (spins, key)
pairs runs replicas with keys of their own.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..core._errors import InputError
from ..core._flows import AbstractFlow
from ..core._state import host_values
from ._rigid_body import as_float_array, is_concrete
from ._spin_flows import turn
from ._spin_lattice import SpinLattice, _present, vertex_colours
from ._splitting import splitting


def check_number(value, name: str, allowed: str = ">= 0"):
    """A finite scalar >= 0 (or > 0 with ``allowed='> 0'``), checked where concrete."""
    arr = as_float_array(value, name)
    if arr.ndim != 0:
        raise InputError(f"{name} must be one number, got shape {tuple(arr.shape)}")
    if is_concrete(arr):
        v = float(host_values(arr))
        ok = np.isfinite(v) and (v > 0 if allowed == "> 0" else v >= 0)
        if not ok:
            raise InputError(f"{name} must be a finite number {allowed}, got {v!r}")
    return arr


def damp_towards(s, field, rate_t):
    """Each spin turned towards ``field`` B (frozen) by the exact LLG damping over time t:
    tan(θ/2) ← tan(θ/2) e^{−λ|S||B|t} (θ the angle to B); ``rate_t`` = λ t (zero off the moving
    sites). Written without trigonometry: with τ = tan(Δ/2) of the turn Δ = θ_0 − θ_t,
    S ← S + [−2τ² S + 2τ (B|S|² − S (S·B))/|S × B|] / (1 + τ²), a rotation about S × B."""
    a = jnp.sum(s * field, axis=-1, keepdims=True)  # |S||B| cos θ
    b = jnp.linalg.norm(jnp.cross(s, field), axis=-1, keepdims=True)  # |S||B| sin θ
    r = jnp.sqrt(a * a + b * b)  # |S||B|
    tiny = jnp.finfo(s.dtype).tiny
    t0 = jnp.where(a >= 0, b / jnp.maximum(r + a, tiny), (r - a) / jnp.maximum(b, tiny))  # tan(θ/2), stably
    t1 = t0 * jnp.exp(-rate_t * r)
    tau = (t0 - t1) / (1 + t0 * t1)
    perpendicular = (field * jnp.sum(s * s, axis=-1, keepdims=True) - s * a) / jnp.maximum(b, tiny)
    return s + (2 * tau / (1 + tau * tau)) * (perpendicular - tau * s)


def damp_anisotropy(s, axis, anisotropy, rate_t):
    """The exact LLG damping of H = −K (n·S)² over time t: S turns in the plane of S and n,
    tan φ ← tan φ e^{−2λK|S|²t} (φ the angle to n; K > 0 towards the nearer pole, K < 0 towards
    the equator); ``rate_t`` = λ t. With (cos, sin) of the turn Δ = φ_0 − φ_t from
    a = S·n, b = |S × n|: S ← S + (cos Δ − 1) S + sin Δ (n|S|² − S a)/b, cos Δ ≥ 0."""
    a = jnp.sum(s * axis, axis=-1, keepdims=True)
    ss = jnp.sum(s * s, axis=-1, keepdims=True)
    b2 = jnp.maximum(ss - a * a, 0.0)  # |S × n|², n a unit vector
    e = jnp.exp(-2 * rate_t * anisotropy * ss)
    q = jnp.sqrt(a * a + b2)
    r = jnp.sqrt(a * a + b2 * e * e)
    cos = (a * a + b2 * e) / jnp.maximum(q * r, jnp.finfo(s.dtype).tiny)
    sin_b = a * (1 - e) / jnp.maximum(q * r, jnp.finfo(s.dtype).tiny)  # sin Δ / b
    sin2 = sin_b * sin_b * b2
    return s + (-sin2 / (1 + cos)) * s + sin_b * (axis * ss - s * a)


class Langevin(AbstractFlow):
    """One sLLG step ``step((spins, key), h) -> (spins, key)`` (module docstring): the
    Hamiltonian step ``hamiltonian`` (a registry scheme on the exact bond flows) for h/2, the
    damping–noise sweep over the sublattices ``masks`` for h, the Hamiltonian step for h/2.
    ``temperature`` T and ``damping`` λ are traced (a new value reuses the compiled loop;
    ``vmap`` sweeps them). Built by ``langevin``.

    >>> import jax, jaxsplit
    >>> square = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("square", 4), exchange=1.0)
    >>> step = jaxsplit.langevin(square, temperature=1.0, damping=0.2)
    >>> len(step.masks), isinstance(step.hamiltonian, jaxsplit.Composition)   # two sublattices; a Strang step
    (2, True)
    >>> spins, key = step((square.uniform(), jax.random.PRNGKey(0)), 0.05)
    >>> spins.shape, key.shape
    ((16, 3), (2,))
    """

    system: SpinLattice
    hamiltonian: AbstractFlow
    temperature: jax.Array
    damping: jax.Array
    masks: jax.Array  # (K, N, 1): 1.0 on the sites of sublattice k

    def _field(self, s):
        """∂(exchange + DM + XXZ + Zeeman)/∂S_i: frozen on a sublattice while it moves."""
        return jax.grad(lambda y: jnp.sum(self.system._no_anisotropy_energy(y)))(s)

    def _sublattice(self, s, mask, tau, noise):
        """damping(τ/2) · noise(τ) · damping(τ/2) on the sites of ``mask``."""
        dtype = s.dtype
        lam = jnp.asarray(self.damping, dtype)
        field = -self._field(s)  # B_eff = −∂H/∂S_i, unchanged while this sublattice turns
        sigma = jnp.sqrt(2 * lam * jnp.asarray(self.temperature, dtype) * tau) * mask
        half = (0.5 * lam * tau) * mask
        s = damp_towards(s, field, half)
        s = turn(s, sigma * noise)
        return damp_towards(s, field, half)

    def _anisotropy(self, s, tau):
        dtype = s.dtype
        k = jnp.broadcast_to(jnp.asarray(self.system.anisotropy, dtype), (self.system.n_sites,))[:, None]
        return damp_anisotropy(s, jnp.asarray(self.system.axis, dtype), k, jnp.asarray(self.damping, dtype) * tau)

    def __call__(self, state, h):
        spins, key = state
        s = self.system.sites(spins)
        h = jnp.asarray(h, s.dtype)
        key, draw = jax.random.split(key)
        # one draw per site for the forward sweep and one for the backward sweep (the
        # sublattices are disjoint, so a colour's masked share is independent of the others');
        # drawn in float32 (2.5x cheaper than float64 here; their 24-bit resolution is far
        # below any statistical error, and the rotations stay in the state's dtype)
        noise = jax.random.normal(draw, (2,) + s.shape, jnp.float32).astype(s.dtype)
        masks = jnp.asarray(self.masks, s.dtype)  # (K, N, 1)
        k = masks.shape[0]
        visits = (masks[jnp.asarray(list(range(k)) + list(range(k - 1, -1, -1)))],
                  jnp.asarray([0] * k + [1] * k))  # forward over the colours, then back

        def visit(y, sweep):
            mask, which = sweep
            return self._sublattice(y, mask, h / 2, noise[which]), None

        anisotropic = _present(self.system.anisotropy)
        s = self.hamiltonian(s, h / 2)
        if anisotropic:
            s = self._anisotropy(s, h / 2)
        s = jax.lax.scan(visit, s, visits)[0]  # one compiled visit, whatever the colours
        if anisotropic:
            s = self._anisotropy(s, h / 2)
        s = self.hamiltonian(s, h / 2)
        return s.reshape(jnp.shape(spins)), key

    @property
    def is_group(self) -> bool:
        return False

    def check_state(self, x):
        if not (isinstance(x, tuple | list) and len(x) == 2):
            raise InputError("a Langevin state is a pair (spins, key), key = jax.random.PRNGKey(seed); got "
                             f"{type(x).__name__}")
        spins, key = x
        key = jnp.asarray(key)
        if key.dtype != jnp.uint32 or key.shape[-1:] != (2,):
            raise InputError("the key of a Langevin state must be a raw key jax.random.PRNGKey(seed) (uint32, shape "
                             f"(2,)), got dtype {key.dtype}, shape {tuple(key.shape)}")
        self.system.check_state(spins)
        return x


def langevin(system, temperature, damping, scheme="strang") -> Langevin:
    """Stochastic LLG dynamics of a spin lattice at ``temperature`` T with damping λ: a step
    ``step((spins, key), h)`` for ``integrate`` (see ``jaxsplit.systems._spin_langevin``).

    ``system`` a ``spin_lattice``; ``temperature`` >= 0 and ``damping`` >= 0 finite numbers
    (k_B = 1; the noise is 2λT); ``scheme`` the registry scheme of the Hamiltonian part (on
    the exact bond flows). Every |S_i| is kept to round-off; the stationary distribution is
    exp(−H/T) up to a bias that vanishes with h.

    >>> import jax, jax.numpy as jnp, jaxsplit
    >>> chain = jaxsplit.spin_lattice(jaxsplit.lattices.lattice("chain", 16), exchange=1.0)
    >>> step = jaxsplit.langevin(chain, temperature=0.5, damping=0.5)
    >>> sol = jaxsplit.integrate(step, (chain.uniform(), jax.random.PRNGKey(0)), 0.05, 200)
    >>> spins, key = sol.final
    >>> bool(jnp.max(jnp.abs(jnp.linalg.norm(spins, axis=-1) - 1)) < 1e-13)
    True
    """
    if not isinstance(system, SpinLattice):
        raise InputError(f"langevin acts on a spin lattice (jaxsplit.spin_lattice), got {type(system).__name__}")
    temperature = check_number(temperature, "temperature")
    damping = check_number(damping, "damping")
    masks = jnp.stack([system._mask(group) for group in vertex_colours(system.lattice)])
    return Langevin(system, splitting(system, scheme, "bonds"), temperature, damping, masks)
