"""``python -m jaxsplit.launch -n N -- TARGET [ARGS ...]``: N local processes of one JAX run.

TARGET is a Python script (``run.py``, which joins with
``jaxsplit.distributed.initialize_from_env()``), ``-m MODULE``, or the arguments of the
``jaxsplit`` command line (``simulate ...``; the command line joins by itself). Each process
gets the coordinator's address (127.0.0.1 and a free port, or ``--port``), the number of
processes and its rank in ``JAXSPLIT_COORDINATOR``, ``JAXSPLIT_NUM_PROCESSES`` and
``JAXSPLIT_PROCESS_ID`` (``jaxsplit.distributed``); standard streams are shared.

Signals: SIGINT and SIGTERM are forwarded once to every process (each runs in its own
process group, so a Ctrl-C at the terminal reaches it once, through the launcher); a second
signal kills them. Processes of one run wait for each other in every collective, so when
one fails the others are ended after ``GRACE_SECONDS`` (they would otherwise wait out
JAX's heartbeat). Exit status: 130 after an interrupt; else the worst status of the
processes that ended on their own (a process killed by signal s counts as 128 + s); 2 with
one line on stderr for a bad ``-n``, a bad ``--port`` or a missing target.
"""

import os
import signal
import socket
import subprocess
import sys
import time

from . import _bounds, distributed
from ._errors import InputError

EXIT_INTERRUPTED = 130
MAX_PROCESSES = 256  # one JAX runtime per process; more than a host's cores is a mistake, not a run
GRACE_SECONDS = 3.0  # after one process failed, the others may still print their own error
POLL_SECONDS = 0.05

USAGE = """\
usage: python -m jaxsplit.launch -n N [--port PORT] [--] TARGET [ARGS ...]

  TARGET: a script (run.py ARGS), -m MODULE ARGS, or jaxsplit command-line arguments
  (simulate --t-end 10 ...). Each of the N processes joins through
  jaxsplit.distributed.initialize_from_env() (the command line calls it itself).

exit status: 130 interrupted; else the worst status of the processes; 2 bad arguments."""


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the kernel's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def parse(argv: list[str]) -> tuple[int, int | None, list[str]]:
    """(number of processes, port or None, the command after the options)."""
    n, port, i = None, None, 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            i += 1
            break
        name, eq, inline = arg.partition("=")
        if name in ("-n", "--processes", "--port"):
            if eq:
                value = inline
            elif i + 1 < len(argv):
                value, i = argv[i + 1], i + 1
            else:
                raise InputError(f"{name} needs a value")
            if name == "--port":
                port = _integer(value, "--port", 1, 65535, "a TCP port")
            else:
                n = _integer(value, "-n", 1, MAX_PROCESSES, "one JAX runtime per process")
            i += 1
        elif arg.startswith("-n") and arg[2:]:
            n = _integer(arg[2:], "-n", 1, MAX_PROCESSES, "one JAX runtime per process")
            i += 1
        elif arg in ("-h", "--help"):
            print(USAGE)
            raise SystemExit(0)
        else:
            break
    if n is None:
        raise InputError("-n (the number of processes) is required, e.g. -n 2")
    command = argv[i:]
    if not command:
        raise InputError("nothing to run: give a script, -m MODULE or jaxsplit arguments after --")
    return n, port, command


def _integer(text: str, name: str, low: int, high: int, why: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"{name} must be an integer in [{low}, {high:,}], got {text!r}") from None
    return _bounds.count(value, name, low, high, why)


def child_command(command: list[str]) -> list[str]:
    """The command each process runs: a script or ``-m MODULE`` under this Python, anything
    else as the ``jaxsplit`` command line."""
    first = command[0]
    if first == "-m" or first.endswith(".py") or os.path.isfile(first):
        return [sys.executable, *command]
    return [sys.executable, "-m", "jaxsplit", *command]


def run(n: int, command: list[str], port: int | None = None) -> int:
    """Start the n processes, forward signals, wait; the exit status (see the module docstring)."""
    address = f"127.0.0.1:{port or free_port()}"
    argv = child_command(command)
    received: list[int] = []
    procs: list[subprocess.Popen] = []

    def forward(signum, _frame):
        received.append(signum)
        for p in procs:
            if p.poll() is None:
                try:
                    p.send_signal(signum if len(received) == 1 else signal.SIGKILL)
                except ProcessLookupError:
                    pass

    previous = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)}
    killed: set[int] = set()  # ranks ended by the launcher after another failed: not counted
    try:
        for rank in range(n):
            env = dict(os.environ, **{distributed.COORDINATOR: address, distributed.NUM_PROCESSES: str(n),
                                      distributed.PROCESS_ID: str(rank)})
            procs.append(subprocess.Popen(argv, env=env, start_new_session=True))
            if received:
                break
        failed_at = None
        while not all([p.poll() is not None for p in procs]):  # a list: every process polled
            if failed_at is None and not received and any(p.returncode not in (None, 0) for p in procs):
                failed_at = time.monotonic()
            if failed_at is not None and time.monotonic() - failed_at > GRACE_SECONDS:
                for rank, p in enumerate(procs):
                    if p.poll() is None:
                        p.kill()
                        killed.add(rank)
            time.sleep(POLL_SECONDS)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if received:
        return EXIT_INTERRUPTED
    return max((_status(p.returncode) for rank, p in enumerate(procs) if rank not in killed), default=0)


def _status(code: int) -> int:
    return 128 - code if code < 0 else code


def main(argv=None) -> int:
    try:
        n, port, command = parse(sys.argv[1:] if argv is None else list(argv))
    except InputError as err:
        print(f"jaxsplit.launch: error: {err}", file=sys.stderr)
        return 2
    return run(n, command, port)


if __name__ == "__main__":
    sys.exit(main())
