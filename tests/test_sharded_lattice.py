"""A lattice and a batch of bodies laid out over 4 forced CPU devices
(``jaxsplit.distributed.shard``) give the one-device result, compiled once; a lattice that does
not divide over the mesh, a bad process count and an unreachable coordinator are one-line
errors; under the launcher only process 0 writes the command line's outputs.

Cost: one child process (4 devices must be forced before JAX starts: XLA_FLAGS) and one short
command line that fails to reach its coordinator; the rest runs here, without JAX's backend.
"""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import with_test_xla_flags

from jaxsplit import distributed
from jaxsplit.core._errors import InputError

SHARD_TOL = 1e-13  # acceptance: 4 devices equal 1 device to 1e-13

FOUR_DEVICES = textwrap.dedent("""
    import sys
    import jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    import jaxsplit
    from jaxsplit import distributed
    from jaxsplit.core._integrate import compilations
    from jaxsplit.lattices import lattice

    assert len(jax.devices()) == 4, jax.devices()
    mesh = distributed.mesh()
    out = {}
    # slabs of a simple-cubic lattice (8 planes) with site terms; the DM and XXZ
    # pieces and order 6 are covered across processes (tests/test_distributed.py)
    system = jaxsplit.spin_lattice(lattice("simple-cubic", (8, 4, 4)), exchange=1.0, anisotropy=0.3,
                                   field=(0.1, 0.0, 0.2))
    step = jaxsplit.splitting(system, "strang", "bonds")
    s0 = np.asarray(system.random_state(3))  # (N, 3), sites row-major: slabs of 2 planes (a lattice-shaped
    # state shards the same way, but compiles 4x slower here: the flows reshape it in every sub-flow)
    one = jaxsplit.integrate(step, s0, 0.05, 12, save_every=4).x
    before = compilations()
    xs = distributed.shard(s0, mesh)
    four = jaxsplit.integrate(step, xs, 0.05, 12, save_every=4)
    again = jaxsplit.integrate(step, distributed.shard(s0[::-1].copy(), mesh), 0.02, 12, save_every=4)
    out["compiled"] = compilations() - before       # new values, new h: one compilation
    out["spec"] = four.final.sharding.spec == jax.sharding.PartitionSpec("sites")
    out["spins"] = float(np.max(np.abs(np.asarray(four.x) - np.asarray(one))))
    out["moved"] = float(np.max(np.abs(np.asarray(one)[-1] - s0)))
    # a batch of 8 free bodies, their inertias spread too
    m0 = np.random.default_rng(1).normal(size=(8, 3))
    inertia = np.tile([2.0, 1.5, 1.0], (8, 1)) * np.linspace(1, 2, 8)[:, None]
    run = lambda m, i: jaxsplit.integrate(jaxsplit.splitting(jaxsplit.RigidBody(i), "strang", "casimir",
                                                              shift=1), m, 0.1, 30).final
    out["bodies"] = float(np.max(np.abs(np.asarray(run(distributed.shard(m0), distributed.shard(inertia)))
                                        - np.asarray(run(m0, inertia)))))
    try:
        distributed.shard(np.zeros((6, 4, 4, 3)), mesh)
    except ValueError as err:
        out["error"] = str(err)
    print(repr(out))
""")


def _child_env(**extra):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    for name in ("XLA_FLAGS", distributed.COORDINATOR, distributed.NUM_PROCESSES, distributed.PROCESS_ID):
        env.pop(name, None)
    return env | {"XLA_FLAGS": with_test_xla_flags()} | extra


def test_four_devices_equal_one_device_compiled_once(tmp_path):
    env = _child_env(XLA_FLAGS=with_test_xla_flags("--xla_force_host_platform_device_count=4"))
    proc = subprocess.run([sys.executable, "-c", FOUR_DEVICES], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=180, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = eval(proc.stdout.strip().splitlines()[-1])
    assert out["spins"] <= SHARD_TOL and out["bodies"] <= SHARD_TOL, out
    assert out["moved"] > 0.05, out  # the spins moved
    assert out["compiled"] == 1, out
    assert out["spec"], out  # laid out as given
    assert out["error"] == ("cannot split a leading axis of 6 (shape (6, 4, 4, 3)) over the 4 devices of the mesh: "
                            "it must be a multiple of 4 (a lattice's first axis, or the batch size)"), out


def test_bad_process_count_is_one_line(monkeypatch):
    monkeypatch.setattr(distributed, "_JOINED", [])
    monkeypatch.setenv(distributed.COORDINATOR, "127.0.0.1:1234")
    for count, rank, message in (("0", "0", "must be in [0, JAXSPLIT_NUM_PROCESSES) = [0, 0), got 0"),
                                 ("2", "2", "must be in [0, JAXSPLIT_NUM_PROCESSES) = [0, 2), got 2"),
                                 ("two", "0", "must be integers, got 'two' and '0'")):
        monkeypatch.setenv(distributed.NUM_PROCESSES, count)
        monkeypatch.setenv(distributed.PROCESS_ID, rank)
        with pytest.raises(InputError) as err:
            distributed.initialize_from_env()
        assert message in str(err.value) and "\n" not in str(err.value)
    monkeypatch.setenv(distributed.NUM_PROCESSES, "2")
    monkeypatch.setenv(distributed.PROCESS_ID, "1")
    monkeypatch.setenv(distributed.TIMEOUT, "soon")
    with pytest.raises(InputError, match="JAXSPLIT_INITIALIZATION_TIMEOUT must be a whole number of seconds"):
        distributed.initialize_from_env()


def test_unreachable_coordinator_is_one_line(tmp_path):
    """JAX's own client aborts the process (a fatal log and a stack dump) when the coordinator
    does not answer; the probe before it gives one line and status 2, after the timeout."""
    from jaxsplit.launch import free_port

    env = _child_env(**{distributed.COORDINATOR: f"127.0.0.1:{free_port()}", distributed.NUM_PROCESSES: "2",
                        distributed.PROCESS_ID: "1", distributed.TIMEOUT: "1"})
    proc = subprocess.run([sys.executable, "-m", "jaxsplit", "schemes"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=60, check=False)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr[-2000:]
    assert proc.stderr.startswith("jaxsplit: error: process 1 of 2 could not reach the coordinator at 127.0.0.1:")
    assert "within 1 s" in proc.stderr


def test_coordinator_address_process_zero_cannot_listen_at(monkeypatch):
    with pytest.raises(InputError, match=r"process 0 of 2 cannot listen at 192\.0\.2\.1:"):
        distributed._reachable("192.0.2.1:1234", 0, 2, 1)  # TEST-NET-1: no address of this host


def test_only_process_zero_writes(tmp_path, monkeypatch):
    from jaxsplit.cli import _io

    existing = tmp_path / "run.npz"
    existing.write_bytes(b"process 0's")
    monkeypatch.setattr(distributed, "_JOINED", [(1, 2)])  # process 1 of 2
    with _io.Outputs() as outputs:
        path = outputs.file(existing, "trajectory")  # no --force: process 0 owns that check
        assert path == existing
        outputs.write_bytes(path, b"process 1's")
        outputs.write_npz(outputs.file(tmp_path / "other.npz", "figure"), {"a": np.zeros(2)})
        assert outputs.directory(tmp_path / "sweep", "--out directory") == tmp_path / "sweep"
    assert existing.read_bytes() == b"process 0's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]  # no file, lock or directory made
    monkeypatch.setattr(distributed, "_JOINED", [(0, 2)])  # process 0 writes as alone
    with _io.Outputs() as outputs:
        outputs.write_npz(outputs.file(tmp_path / "other.npz", "figure"), {"a": np.zeros(2)})
        with pytest.raises(InputError, match="exists; pass --force"):
            outputs.file(existing, "trajectory")
    assert (tmp_path / "other.npz").exists()
