"""The native pair kernel (``jaxsplit._native``, ``systems/_pair_kernel.cc``) against the XLA
kernel it replaces: the same map to a few ulp in every layout (chain, square, simple cubic, a
4-d lattice, leading batch axes, both parities, the wrapped pair, a lattice of 2), both tiers,
float64 and float32, under vmap and grad; and what happens where it cannot be built."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxsplit import _native
from jaxsplit.systems import _spin_pairs as pairs

ULPS = 16  # measured: at most 7 ulp between the two (fused multiply-adds, the C library's cos and sin)
LAYOUTS = [((), (8,)), ((2,), (6, 4)), ((), (4, 6, 8)), ((2,), (4, 2, 6)), ((), (2,))]
JT = (0.1, 0.9, 2.0, 6.0, -3.0)  # tier 0 (2|J t| max s <= 2) and the full range beyond it


def _tier(jt):
    return (pairs.SAFETY * jnp.abs(jt) > pairs.TIERS[0]).astype(jnp.int32)  # unit spins


@pytest.fixture(scope="module")
def built():
    """The kernel, built (a failed build fails; a machine without a compiler skips, saying so)."""
    if not _native.pair_kernel_available(np.float64):
        status = _native.native_status()["pair flow"]
        if status.startswith("no C++ compiler"):
            pytest.skip(status)
        pytest.fail(f"the native kernel did not build on this machine: {status}")
    return True


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_native_kernel_is_the_xla_kernel(built, dtype):
    rng = np.random.default_rng(0)
    worst = 0.0
    for lead, shape in LAYOUTS:
        x = rng.normal(size=lead + (3,) + shape)
        x = jnp.asarray(x / np.linalg.norm(x, axis=len(lead), keepdims=True), dtype)
        d = len(shape)
        native = jax.jit(pairs._native_flow, static_argnums=(3, 4, 5))
        xla = jax.jit(pairs._xla_flow, static_argnums=(3, 4, 5))
        for axis in range(d):
            for parity in (0, 1):
                for jt in JT:
                    jt = jnp.asarray(jt, dtype)
                    a, b = native(x, jt, _tier(jt), d, axis, parity), xla(x, jt, _tier(jt), d, axis, parity)
                    assert a.dtype == dtype and a.shape == x.shape
                    worst = max(worst, float(jnp.max(jnp.abs(a - b))) / float(np.finfo(dtype).eps))
                    assert float(jnp.max(jnp.abs(a - x))) > 1e-3  # it turned the spins
    assert worst <= ULPS, worst


def test_vmap_over_jt_and_the_gradient(built):
    """A vmap of J t gives each batch element its own J t and tier; the flow's closed-form JVP
    (``_pair_flow_jvp``) differentiates the native primal like the XLA one."""
    x = jnp.asarray(np.random.default_rng(1).normal(size=(3, 4, 6)))
    jts = jnp.asarray([0.1, 0.5, 3.0])  # tiers 0, 0, 1 in one call
    native = jax.vmap(lambda jt: pairs._native_flow(x, jt, _tier(jt), 2, 1, 1))(jts)
    xla = jax.vmap(lambda jt: pairs._xla_flow(x, jt, _tier(jt), 2, 1, 1))(jts)
    assert float(jnp.max(jnp.abs(native - xla))) < 1e-14

    def loss(jt, y):
        return jnp.sum(jnp.sin(pairs._pair_flow(y, jt, _tier(jt), 2, 0, 1)) ** 2)

    grads = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(0.3), x)
    original = _native.pair_kernel_available
    try:
        _native.pair_kernel_available = lambda dtype: False
        reference = jax.jit(jax.grad(lambda jt, y: loss(jt, y), argnums=(0, 1)))(jnp.asarray(0.3), x)
    finally:
        _native.pair_kernel_available = original
    for g, r in zip(grads, reference, strict=True):
        assert float(jnp.max(jnp.abs(g - r))) < 1e-13


def test_a_program_calls_it_only_where_it_applies(built):
    x = jnp.ones((3, 4, 4)) / jnp.sqrt(3.0)
    text = jax.jit(lambda y: pairs._pair_flow(y, 0.1, 0, 2, 0, 0)).lower(x).as_text()
    assert _native.TARGET in text
    assert not _native.pair_kernel_available(jnp.bfloat16) and not _native.pair_kernel_available(jnp.int32)


def test_without_a_compiler_switched_off_or_damaged_the_xla_path_runs_and_says_why(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXSPLIT_CACHE", str(tmp_path))
    try:
        monkeypatch.setenv("CXX", "/bin/false")
        _native._library.cache_clear()
        with pytest.warns(RuntimeWarning, match="not built, the XLA path runs"):
            assert _native._library() is None
        assert _native.native_status()["pair flow"].startswith("build failed (/bin/false)")
        assert not list(tmp_path.iterdir())  # nothing half-written left in the cache
        monkeypatch.setenv("JAXSPLIT_NATIVE", "0")
        _native._library.cache_clear()
        assert _native._library() is None and _native.native_status()["pair flow"] == "off (JAXSPLIT_NATIVE=0)"
        monkeypatch.delenv("JAXSPLIT_NATIVE")
        monkeypatch.delenv("CXX")
        _native._library.cache_clear()
        monkeypatch.setattr(_native, "_library", lambda: str(tmp_path / "damaged.so"))  # a damaged cached library
        (tmp_path / "damaged.so").write_bytes(b"not a library")
        _native._registered.cache_clear()
        with pytest.warns(RuntimeWarning, match="not loaded, the XLA path runs"):
            assert not _native._registered()
    finally:
        monkeypatch.undo()
        _native._library.cache_clear()
        _native._registered.cache_clear()
        _native._registered()  # as it was (registering the target again is harmless): the status names the library
