"""Sharded sweeps (4 forced CPU devices, in a subprocess) equal the single-device sweep."""

import json
import os
import subprocess
import sys
import textwrap

from conftest import with_test_xla_flags

SHARD_TOL = 1e-15  # acceptance: sharded and unsharded sweeps agree to 1e-15

SCRIPT = textwrap.dedent("""
    import json, jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    import jaxsplit
    assert len(jax.devices()) == 4, jax.devices()
    cases = jaxsplit.sweep_cases(sampling="random", n_samples=203, seed=7, h_range=(0.05, 0.4))
    kw = dict(t_end=4.0, split="axes", chunk_size=64)
    sharded = jaxsplit.sweep("yoshida-6a", cases, **kw)
    single = jaxsplit.sweep("yoshida-6a", cases, devices=jax.devices()[:1], **kw)
    diff = {k: float(np.max(np.abs(np.asarray(sharded[k], float) - np.asarray(single[k], float))))
            for k in sharded}
    print(json.dumps({"devices": len(jax.devices()), "diff": diff,
                      "max_error": float(np.max(single["error"]))}))
""")


def test_sharded_sweep_equals_single_device():
    env = dict(os.environ, XLA_FLAGS=with_test_xla_flags("--xla_force_host_platform_device_count=4"), JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["devices"] == 4
    assert result["max_error"] > 0  # the comparison is not between two empty results
    for key, diff in result["diff"].items():
        assert diff <= SHARD_TOL, (key, diff)
