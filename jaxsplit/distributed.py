"""Joining a run of several processes: ``initialize_from_env`` reads what the launcher
(``python -m jaxsplit.launch``) or a cluster's job script put in the environment and calls
``jax.distributed.initialize`` once; without those variables it does nothing, so the same
script runs alone, under the launcher, or on a cluster unchanged (``docs/distributed.md``).

The variables (the launcher sets all three; on a cluster set them, or let JAX read SLURM's):

* ``JAXSPLIT_COORDINATOR``: ``host:port`` of process 0's coordinator;
* ``JAXSPLIT_NUM_PROCESSES``: how many processes take part;
* ``JAXSPLIT_PROCESS_ID``: this process's rank, 0 … n − 1.

On the CPU the processes' collectives go through gloo
(``jax_cpu_collectives_implementation``), set here before JAX starts its backend.
"""

import contextlib
import os
import sys

from ._errors import InputError

COORDINATOR = "JAXSPLIT_COORDINATOR"
NUM_PROCESSES = "JAXSPLIT_NUM_PROCESSES"
PROCESS_ID = "JAXSPLIT_PROCESS_ID"
# Seconds a process waits for the others at the coordinator: a rank that never comes (it
# failed before joining) or an unreachable coordinator is an error after this long, not a hang.
INITIALIZATION_TIMEOUT = 60

_JOINED: list[tuple[int, int]] = []  # (process id, number of processes) once joined


def launched() -> bool:
    """Whether this process was started as one of several (the variables are set)."""
    return COORDINATOR in os.environ


def _rank_and_count() -> tuple[str, int, int]:
    address = os.environ[COORDINATOR]
    try:
        n = int(os.environ[NUM_PROCESSES])
        rank = int(os.environ[PROCESS_ID])
    except (KeyError, ValueError) as err:
        raise InputError(f"{COORDINATOR} is set ({address}) but {NUM_PROCESSES} and {PROCESS_ID} must be "
                         f"integers, got {os.environ.get(NUM_PROCESSES)!r} and {os.environ.get(PROCESS_ID)!r}") from err
    if not (n >= 1 and 0 <= rank < n):
        raise InputError(f"{PROCESS_ID} must be in [0, {NUM_PROCESSES}) = [0, {n}), got {rank}")
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"{COORDINATOR} must be host:port, got {address!r}")
    return address, rank, n


def initialize_from_env() -> tuple[int, int]:
    """Join the run this process was launched into; ``(process id, number of processes)``.

    Without ``JAXSPLIT_COORDINATOR`` in the environment (not launched), nothing happens and
    the answer is ``(0, 1)``. Called again, it answers the same without joining twice. Call
    it before any array is made (JAX's backend starts with the first one).

    >>> import jaxsplit.distributed
    >>> jaxsplit.distributed.initialize_from_env()  # not launched: a no-op
    (0, 1)
    """
    if _JOINED:
        return _JOINED[0]
    if not launched():
        return (0, 1)
    address, rank, n = _rank_and_count()
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        jax.distributed.initialize(coordinator_address=address, num_processes=n, process_id=rank,
                                   initialization_timeout=INITIALIZATION_TIMEOUT)
    except Exception as err:  # noqa: BLE001 - XLA's errors are not one type; the message is the point
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InputError(f"process {rank} of {n} could not join the coordinator at {address} within "
                         f"{INITIALIZATION_TIMEOUT} s: {first}") from err
    _JOINED.append((rank, n))
    sys.excepthook = _ending_at_once(sys.excepthook)
    return _JOINED[0]


def _ending_at_once(previous):
    """An uncaught exception ends the process at once (status 1, after its traceback): JAX's
    exit hook would wait for the other processes, which wait for this one in a collective;
    the launcher then ends the others."""

    def hook(kind, value, traceback):
        previous(kind, value, traceback)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(1)

    return hook


def leave() -> None:
    """Leave the run (``jax.distributed.shutdown``: waits for the others) when joined; for a
    process that ends by ``os._exit`` (the command line), which skips JAX's own exit hook. The
    coordinator lives in process 0: ending it before the others finish aborts them."""
    if _JOINED:
        import jax

        jax.distributed.shutdown()
        _JOINED.clear()
