"""Two local processes through the launcher (``python -m jaxsplit.launch -n 2``, gloo
collectives on 127.0.0.1) give the one-process result: a spin lattice and a batch of free
bodies, each a global array sharded over both processes' devices. And the launcher's
one-line errors and its signal policy.

Cost: three launches of two small processes (a few seconds each on two cores).
"""

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
from conftest import with_test_xla_flags

DIST_TOL = 1e-13  # acceptance: 2 processes equal 1 process to 1e-13

SCRIPT = textwrap.dedent("""
    import sys
    import jaxsplit.distributed
    rank, n = jaxsplit.distributed.initialize_from_env()
    import jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    from jax.experimental import multihost_utils
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
    import jaxsplit
    from jaxsplit.lattices import lattice

    assert jax.process_count() == n and len(jax.devices()) == n, (jax.process_count(), jax.devices())
    mesh = Mesh(np.array(jax.devices()), ("p",))

    def spread(a):  # a global array: rows split over the processes' devices
        return jax.make_array_from_callback(a.shape, NamedSharding(mesh, P("p")), lambda index: a[index])

    def whole(x):
        return np.asarray(multihost_utils.process_allgather(x, tiled=True))

    system = jaxsplit.spin_lattice(lattice("square", 4), exchange=1.0, anisotropy=0.3, field=(0.1, 0.0, 0.2))
    s0 = np.asarray(system.perturbed(system.uniform((0.0, 0.0, 1.0)), 0.2, seed=3))
    spins = jaxsplit.integrate(jaxsplit.splitting(system, "yoshida-6a", "bonds"), spread(s0), 0.05, 24, save_every=8)
    assert spins.status == "ok"
    m0 = np.random.default_rng(1).normal(size=(8, 3))
    body = jaxsplit.RigidBody(spread(np.tile([2.0, 1.5, 1.0], (8, 1))))  # the parameters spread too
    bodies = jaxsplit.integrate(jaxsplit.splitting(body, "kahan-li-6", "casimir", shift=1), spread(m0), 0.1, 30,
                                save_every=10)
    out = dict(spins=whole(spins.x), bodies=whole(bodies.x), t=whole(bodies.t))
    if rank == 0:
        np.savez(sys.argv[1], **out)
""")


def _launch(args, tmp_path, **kw):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = with_test_xla_flags()  # one CPU device per process
    return subprocess.run([sys.executable, "-m", "jaxsplit.launch", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120, check=False, **kw)


def test_two_processes_equal_one(tmp_path):
    (tmp_path / "run.py").write_text(SCRIPT)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = with_test_xla_flags()
    one = subprocess.run([sys.executable, "run.py", "one.npz"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=120, check=False)  # not launched: initialize_from_env is a no-op
    assert one.returncode == 0, one.stderr[-3000:]
    two = _launch(["-n", "2", "--", "run.py", "two.npz"], tmp_path)
    assert two.returncode == 0, two.stderr[-3000:]
    a, b = np.load(tmp_path / "one.npz"), np.load(tmp_path / "two.npz")
    assert a["spins"].shape == (4, 16, 3) and a["bodies"].shape == (4, 8, 3)
    for key in ("spins", "bodies", "t"):
        assert np.max(np.abs(a[key] - b[key])) <= DIST_TOL, (key, np.max(np.abs(a[key] - b[key])))
    assert np.max(np.abs(a["spins"][-1] - a["spins"][0])) > 0.01  # the spins moved


def test_bad_process_count_is_one_line(tmp_path):
    for bad in ("0", "two", "100000"):
        proc = _launch(["-n", bad, "--", "run.py"], tmp_path)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith("jaxsplit.launch: error: -n must be an integer in [1, 256]"), proc.stderr
    proc = _launch(["-n", "2"], tmp_path)
    assert proc.returncode == 2 and "nothing to run" in proc.stderr


def test_a_failing_process_ends_the_run_with_its_status(tmp_path):
    (tmp_path / "fail.py").write_text(textwrap.dedent("""
        import time, jaxsplit.distributed
        rank, n = jaxsplit.distributed.initialize_from_env()
        if rank == 1:
            raise ValueError("rank 1 fails")
        time.sleep(60)  # rank 0 would wait for rank 1 in a collective
    """))
    start = time.monotonic()
    proc = _launch(["-n", "2", "--", "fail.py"], tmp_path)
    assert proc.returncode == 1 and "rank 1 fails" in proc.stderr
    assert time.monotonic() - start < 30


def test_interrupt_reaches_every_process_and_exits_130(tmp_path):
    (tmp_path / "wait.py").write_text(textwrap.dedent("""
        import os, signal, sys, time
        rank = os.environ["JAXSPLIT_PROCESS_ID"]
        signal.signal(signal.SIGINT, lambda *_: (open(f"got{rank}", "w").close(), sys.exit(0)))
        open(f"ready{rank}", "w").close()
        time.sleep(60)
    """))
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-m", "jaxsplit.launch", "-n", "2", "--", "wait.py"], cwd=tmp_path,
                            env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not all((tmp_path / f"ready{r}").exists() for r in (0, 1)) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) == 130
    assert (tmp_path / "got0").exists() and (tmp_path / "got1").exists()
