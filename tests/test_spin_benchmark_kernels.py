"""The spin benchmark's hand-written kernels (``benchmarks/_spin_kernels.py``) agree with each
other: ``benchmarks/spins.py`` measures jaxsplit and LAMMPS SPIN against them, and checks
jaxsplit's run against the NumPy loop, so a wrong reference would mislead every figure."""

import importlib.util

import jax.numpy as jnp
import numpy as np
from conftest import ROOT

AGREEMENT = 1e-13  # NumPy's cos/sinc against the fused loop's polynomials, after 12 steps on 4³ spins


def _kernels():
    spec = importlib.util.spec_from_file_location("spin_benchmark_kernels", ROOT / "benchmarks" / "_spin_kernels.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_numpy_loop_and_hand_fused_jax_loop_agree_on_a_4x4x4_lattice():
    k = _kernels()
    s = np.random.default_rng(5).standard_normal((3, 4, 4, 4))
    s /= np.linalg.norm(s, axis=0)
    h, n, exchange = 0.07, 12, -1.3  # antiferromagnetic: the sign of J reaches the rotation's sense
    fused = np.asarray(k.fused_run(exchange, h)(jnp.asarray(s), h, n))
    plain = k.numpy_run(s, h, n, exchange)
    assert fused.dtype == np.float64
    assert np.max(np.abs(fused - plain)) < AGREEMENT
    # and the run moved: the two agree on a trajectory, not on the initial state
    assert np.max(np.abs(plain - s)) > 0.1
    # the two-spin flows keep every |S_i| and the bond flows the energy to the splitting's error
    assert np.max(np.abs(np.linalg.norm(fused, axis=0) - 1)) < AGREEMENT
    assert abs(k.energy(fused, exchange) - k.energy(s, exchange)) < 0.05 * abs(k.energy(s, exchange))
