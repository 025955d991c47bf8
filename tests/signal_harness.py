"""Real processes for the signal and concurrency tests, with JAX imported once.

``Zygote`` starts one Python process that imports ``jaxsplit.cli`` (and every command
module) but initialises no JAX backend (no threads yet, so forking is safe), then forks one
child per run. A child is an ordinary CLI process: it runs ``main(argv)`` with its own
stdout/stderr files and leaves through ``sys.exit``, so interpreter teardown (where an
interrupted XLA once segfaulted) happens for real. Signals come either from outside at any
moment (``Zygote.signal``: the stress runs), or from inside at a chosen phase (a
``trigger``: the deterministic tests), by ``os.kill`` of the child itself:

* ``parse``: while the arguments are parsed (nothing started);
* ``call:MODULE:NAME:N``: just before the N-th call of ``MODULE.NAME`` (e.g. the N-th
  chunk of a run, the N-th file written, or ``_signals:end_process:1``: after ``main``
  decided its status, while the process ends);
* ``during:MODULE:NAME:SECONDS``: SECONDS after the first call of ``MODULE.NAME`` began,
  from a thread, so the signal arrives while the main thread is inside XLA (compiling or
  running).
"""

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

_SERVER = r"""
import functools, importlib, json, os, sys, signal, threading
for name in ("simulate", "sweep", "check", "fit", "paper", "schemes"):
    importlib.import_module("jaxsplit.cli." + name)
import jaxsplit.cli
from jax._src import xla_bridge
if xla_bridge._backends:  # forking a process with XLA's threads running can deadlock the child
    sys.exit("signal_harness: importing jaxsplit.cli initialised a JAX backend")

def serve():
    out = sys.stdout
    for line in sys.stdin:
        req = json.loads(line)
        if "wait" in req:
            _, status = os.waitpid(req["wait"], 0)
            code = os.waitstatus_to_exitcode(status)
            out.write(json.dumps({"status": code}) + "\n"); out.flush()
            continue
        pid = os.fork()
        if pid == 0:
            return req
        out.write(json.dumps({"pid": pid}) + "\n"); out.flush()
    sys.exit(0)

def arm(trigger, sig):
    kind, _, rest = trigger.partition(":")
    if kind == "parse":
        real = jaxsplit.cli.build_parser
        def build_parser():
            os.kill(os.getpid(), sig)
            return real()
        jaxsplit.cli.build_parser = build_parser
        return
    module_name, name, arg = rest.rsplit(":", 2)
    module = importlib.import_module(module_name)
    owner = module
    if "." in name:
        cls, name = name.split(".")
        owner = getattr(module, cls)
    real = getattr(owner, name)
    calls = [0]
    @functools.wraps(real)
    def wrapper(*args, **kwargs):
        calls[0] += 1
        if kind == "call" and calls[0] == int(arg):
            os.kill(os.getpid(), sig)
        if kind == "during" and calls[0] == 1:
            timer = threading.Timer(float(arg), os.kill, (os.getpid(), sig))
            timer.daemon = True
            timer.start()
        return real(*args, **kwargs)
    setattr(owner, name, wrapper)

req = serve()
os.chdir(req["cwd"])
for fd, path in ((1, req["stdout"]), (2, req["stderr"])):
    f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(f, fd)
    os.close(f)
null = os.open(os.devnull, os.O_RDONLY)
os.dup2(null, 0)
if req.get("trigger"):
    arm(req["trigger"], getattr(signal, req["signal"]))
sys.argv = ["jaxsplit", *req["argv"]]
sys.exit(jaxsplit.cli.main())  # as the console script calls it
"""


class Run:
    def __init__(self, zygote, pid, stdout, stderr):
        self.zygote, self.pid, self._stdout, self._stderr = zygote, pid, stdout, stderr
        self.returncode = None
        self.started = time.monotonic()

    def wait(self):
        if self.returncode is None:
            self.returncode = self.zygote._request({"wait": self.pid})["status"]
            self.seconds = time.monotonic() - self.started
        return self

    @property
    def stdout(self):
        return Path(self._stdout).read_text()

    @property
    def stderr(self):
        return Path(self._stderr).read_text()


class Zygote:
    """One warm process forking CLI runs (see the module docstring)."""

    def __init__(self, workdir):
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        root = Path(__file__).resolve().parents[1]
        env = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
                   PYTHONWARNINGS="ignore")
        self.proc = subprocess.Popen([sys.executable, "-c", _SERVER], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env=env, cwd=root)
        self._count = 0

    def _request(self, req):
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the zygote died")
        return json.loads(line)

    def start(self, argv, cwd, *, trigger=None, signal="SIGINT") -> Run:
        self._count += 1
        stdout = self.workdir / f"run{self._count}.out"
        stderr = self.workdir / f"run{self._count}.err"
        reply = self._request({"argv": [str(a) for a in argv], "cwd": str(cwd), "stdout": str(stdout),
                               "stderr": str(stderr), "trigger": trigger, "signal": signal})
        return Run(self, reply["pid"], stdout, stderr)

    def run(self, argv, cwd, **kwargs) -> Run:
        return self.start(argv, cwd, **kwargs).wait()

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def leftovers(directory) -> list[str]:
    """Temporary, lock and staging files of the writer left in ``directory`` (recursively)."""
    return sorted(str(p.relative_to(directory)) for p in Path(directory).rglob(".jaxsplit*"))


@contextlib.contextmanager
def sigint_at_default():
    """SIGINT at its default here and, through this process, in every child, as from a terminal,
    also when started in the background (where SIGINT starts ignored, and the CLI keeps an
    inherited ignore). The suite holds it for its whole session (``conftest.py``)."""
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)  # exec resets a handler to SIG_DFL
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
