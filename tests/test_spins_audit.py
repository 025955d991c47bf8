"""The spin audit's Poisson verdicts against an independent check: the Jacobian by central
finite differences (no automatic differentiation) in DΦ Π DΦᵀ − Π∘Φ."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxsplit.paper import _spins

FD_STEP = 1e-5  # central differences: truncation ~1e-10·|D³Φ|, rounding ~1e-11
FD_FLOOR = 1e-8  # an exact Poisson map's finite-difference defect stays below this
FD_VIOLATION = 1e-5  # a defect above this is a violation the differences cannot produce


def _fd_defect(system, step, x, h):
    flat = np.asarray(x, dtype=float).reshape(-1)
    n = flat.size
    step = jax.jit(step)

    def phi(v):
        return np.asarray(step(jnp.asarray(v.reshape(x.shape)), h)).reshape(-1)

    jac = np.empty((n, n))
    for k in range(n):
        e = np.zeros(n)
        e[k] = FD_STEP
        jac[:, k] = (phi(flat + e) - phi(flat - e)) / (2 * FD_STEP)
    pi = np.asarray(system.poisson_matrix(x))
    pi_after = np.asarray(system.poisson_matrix(jnp.asarray(phi(flat).reshape(x.shape))))
    return float(np.max(np.abs(jac @ pi @ jac.T - pi_after)))


@pytest.mark.parametrize("method", ["sublattice", "sweep"])  # the exact splitting: tests/test_spin_lattice.py
def test_poisson_verdicts_agree_with_finite_differences(method):
    column = _spins.poisson_column("ring-6", method)
    system = _spins._system("ring-6")
    step = _spins._step(system, method)
    h = _spins.DEFECT_STEPS[0]
    fd = _fd_defect(system, step, system.random_state(0), h)
    if column["verdict"] == "not a Poisson map":
        assert fd > FD_VIOLATION
        assert fd == pytest.approx(column["defects"][0], rel=1e-4)  # the same number, two ways
        assert 2.5 < column["power"] < 3.5  # a second-order map's defect: O(h³)
    else:  # a verdict of "Poisson map" must survive the independent check too
        assert column["verdict"] == "Poisson map" and fd < FD_FLOOR
    assert column["verdict"] == "not a Poisson map"  # what the prototype measured, now computed twice
