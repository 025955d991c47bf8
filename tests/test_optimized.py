"""The round-off-critical checks again, compiled as users compile them.

The suite compiles unoptimised (``conftest``: jax_disable_most_optimizations), where XLA forms
no fused multiply-adds; users' programs are optimised, where it does. Every tolerance must hold
both ways: these checks (the rotation kernels' accuracy at every resolved angle, the short
kernels' within their bounds, and a whole run's agreement with the general kernel) run here a
second time in a child process with the optimisations on and XLA's default CPU emitters.
"""

import os
import subprocess
import sys

from conftest import ROOT, users_env

CHECKS = ("resolved_angle or unit_circle or exact_signs or short_kernels_are_accurate "
          "or every_kernel_gives_the_general")


def test_the_kernel_checks_hold_with_xlas_optimisations_on():
    env = users_env(dict(os.environ))
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
                          "--no-header", "-o", "addopts=", str(ROOT / "tests" / "test_kernel.py"), "-k", CHECKS],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert " passed" in run.stdout and "deselected" in run.stdout  # the selection is not empty, nor everything
