"""Joining a run of several processes: ``initialize_from_env`` reads what the launcher
(``python -m jaxsplit.launch``) or a cluster's job script put in the environment and calls
``jax.distributed.initialize`` once; without those variables it does nothing, so the same
script runs alone, under the launcher, or on a cluster unchanged (``docs/distributed.md``).

The variables (the launcher sets all three; on a cluster set them, or let JAX read SLURM's):

* ``JAXSPLIT_COORDINATOR``: ``host:port`` of process 0's coordinator;
* ``JAXSPLIT_NUM_PROCESSES``: how many processes take part;
* ``JAXSPLIT_PROCESS_ID``: this process's rank, 0 … n − 1;
* ``JAXSPLIT_INITIALIZATION_TIMEOUT`` (optional): seconds to wait for the others at the
  coordinator (default 60).

On the CPU the processes' collectives go through gloo
(``jax_cpu_collectives_implementation``), set here before JAX starts its backend.

Laying data out over devices (those of one process, or of all processes of a run): ``mesh()``
is a one-axis ``jax.sharding.Mesh`` over every device, ``shard(x)`` places a state (any
PyTree: a spin lattice's (N, 3) or ``lattice.shape + (3,)`` state, a batch of bodies, a batch
of parameters) on it with each leaf's leading axis split into contiguous slabs, one per
device. ``integrate`` takes the result as it takes any array: one program, compiled once,
partitioned by XLA (GSPMD), which inserts the communication where a flow reads a site held
by another device. This module imports JAX only inside those two functions.
"""

import contextlib
import os
import socket
import sys
import time

from ._errors import InputError

COORDINATOR = "JAXSPLIT_COORDINATOR"
NUM_PROCESSES = "JAXSPLIT_NUM_PROCESSES"
PROCESS_ID = "JAXSPLIT_PROCESS_ID"
# Seconds a process waits for the others at the coordinator: a rank that never comes (it
# failed before joining) or an unreachable coordinator is an error after this long, not a hang.
INITIALIZATION_TIMEOUT = 60
TIMEOUT = "JAXSPLIT_INITIALIZATION_TIMEOUT"

_JOINED: list[tuple[int, int]] = []  # (process id, number of processes) once joined


def process_index() -> int:
    """This process's rank in the run it joined (0 when not launched); no JAX call."""
    return _JOINED[0][0] if _JOINED else 0


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


def _timeout() -> int:
    text = os.environ.get(TIMEOUT, str(INITIALIZATION_TIMEOUT))
    try:
        seconds = int(text)
    except ValueError:
        seconds = 0
    if not 1 <= seconds <= 86400:
        raise InputError(f"{TIMEOUT} must be a whole number of seconds in [1, 86400], got {text!r}")
    return seconds


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
    timeout = _timeout()
    _reachable(address, rank, n, timeout)
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        jax.distributed.initialize(coordinator_address=address, num_processes=n, process_id=rank,
                                   initialization_timeout=timeout)
    except Exception as err:  # noqa: BLE001 - XLA's errors are not one type; the message is the point
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InputError(f"process {rank} of {n} could not join the coordinator at {address} within "
                         f"{timeout} s: {first}") from err
    _JOINED.append((rank, n))
    sys.excepthook = _ending_at_once(sys.excepthook)
    return _JOINED[0]


def _reachable(address: str, rank: int, n: int, timeout: int) -> None:
    """A one-line ``InputError`` where JAX would abort the process (its client ends it with a
    fatal log and a stack dump when the coordinator does not answer in time): process 0 must
    be able to listen at ``address`` (an address of this host, the port free); the others
    must reach it within ``timeout`` seconds (process 0 may start later: retried)."""
    host, _, port = address.rpartition(":")
    host = host.strip("[]")
    if rank == 0:
        try:
            family = socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)[0][0]
            with socket.socket(family, socket.SOCK_STREAM) as s:
                s.bind((host, int(port)))
        except OSError as err:
            raise InputError(f"process 0 of {n} cannot listen at {address} (the coordinator's address must be this "
                             f"host's, its port free): {err.strerror or err}") from None
        return
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host, int(port)), timeout=max(0.1, min(1.0, deadline - time.monotonic()))):
                return
        except OSError as err:
            if time.monotonic() >= deadline:
                raise InputError(f"process {rank} of {n} could not reach the coordinator at {address} within "
                                 f"{timeout} s ({err.strerror or err}); is process 0 running there?") from None
            time.sleep(0.1)


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


MESH_AXIS = "sites"  # the one axis of ``mesh()``: slabs of a lattice, or parts of a batch


def mesh(devices=None, axis: str = MESH_AXIS):
    """A one-axis ``jax.sharding.Mesh`` over ``devices`` (default: every device of every
    process of the run, ``jax.devices()``), its axis named ``axis``.

    >>> import jaxsplit.distributed
    >>> m = jaxsplit.distributed.mesh()
    >>> m.axis_names, m.devices.size >= 1
    (('sites',), True)
    """
    import jax
    import numpy as np

    devices = jax.devices() if devices is None else list(devices)
    if not devices:
        raise InputError("a mesh needs at least one device, got none")
    return jax.sharding.Mesh(np.array(devices), (axis,))


def shard(x, mesh=None):
    """``x`` (an array or any PyTree of arrays) laid out over ``mesh`` (default ``mesh()``):
    each leaf's leading axis split into as many contiguous slabs as the mesh has devices.

    A spin lattice's state ((N, 3), or ``lattice.shape + (3,)``) is cut into slabs along the
    lattice's first axis (sites are numbered row-major); a batch of bodies or of parameters
    into parts of the batch. Across processes every process passes the same whole value
    (``jax.make_array_from_callback``: each keeps only the slabs of its own devices). The
    result is a global ``jax.Array`` that ``integrate`` takes unchanged; a leading axis that
    is not a multiple of the number of devices is a one-line ``InputError`` (a
    ``ValueError``) naming both sizes.

    >>> import jax, jax.numpy as jnp, jaxsplit, jaxsplit.distributed
    >>> x = jaxsplit.distributed.shard(jnp.zeros((8, 3)))
    >>> x.shape, x.sharding.spec == jax.sharding.PartitionSpec("sites")
    ((8, 3), True)
    """
    import jax
    import numpy as np

    mesh = globals()["mesh"]() if mesh is None else mesh
    if not isinstance(mesh, jax.sharding.Mesh) or len(mesh.axis_names) != 1:
        raise InputError(f"shard needs a one-axis jax.sharding.Mesh (jaxsplit.distributed.mesh()), got {mesh!r}")
    n = mesh.devices.size
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(mesh.axis_names[0]))

    def place(leaf):
        if isinstance(leaf, jax.Array) and leaf.sharding == sharding:
            return leaf
        shape = np.shape(leaf)
        if not shape:
            raise InputError(f"shard splits each array's leading axis over the mesh; got a scalar ({leaf!r})")
        if shape[0] % n:
            raise InputError(f"cannot split a leading axis of {shape[0]} (shape {shape}) over the {n} devices of the "
                             f"mesh: it must be a multiple of {n} (a lattice's first axis, or the batch size)")
        if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
            return jax.device_put(leaf, sharding)  # a global array already: the compiler moves it
        values = np.asarray(leaf)
        if values.dtype == np.float64 and not jax.config.jax_enable_x64:
            values = values.astype(np.float32)  # what jnp.asarray would give: never a silent 64-bit surprise
        return jax.make_array_from_callback(shape, sharding, lambda index: values[index])

    return jax.tree_util.tree_map(place, x)
