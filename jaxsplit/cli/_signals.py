"""The one signal policy of the command line: SIGINT and SIGTERM are handled alike.

Why the handler never raises: a ``KeyboardInterrupt`` raised into running code unwinds
through JAX while XLA goes on compiling or computing on its own threads, and the
interpreter's teardown then runs under those threads (``fit`` interrupted during
``backend.compile_and_load`` ended in a segmentation fault at exit). So a signal is only
*recorded*, and what happens next depends on the mode of the moment:

* ``abandon`` (the default; nothing finished would be lost: parsing, compiling, ``check``,
  ``fit``, a claim of the paper audit, whose finished claims are already written): the
  process ends at once with exit status 130 through ``os._exit`` (no teardown racing XLA's
  threads), after the registered clean-ups (lock files, temporary files, what is kept);
* ``defer`` (finished work to keep: the chunks of ``simulate`` and ``sweep``): the command
  looks at ``requested`` between compiled calls, stops, writes what is finished and exits
  130; a second signal abandons;
* ``critical`` (an output being written, the results being printed): only recorded; the
  write completes (the exit status becomes 130).

Each delivered signal is one byte in a pipe (``signal.set_wakeup_fd``) and is acted on
exactly once, by whoever reads its byte: the Python handler (main thread, right after the
delivery, in the mode of that moment) or, when the main thread has not run Python for
``STUCK_SECONDS`` because it waits inside one long compiled call, a helper thread (the
main thread's mode cannot change while it waits). So Ctrl-C ends a fit at once even in the
middle of an XLA computation.

When ``main`` is the process, it ends through ``end_process``: a signal that came at any
moment before the status is decided makes it 130, and no teardown follows.

A signal that was ignored when the process started (``nohup``, background jobs) stays
ignored, as Python itself does for SIGINT.
"""

import contextlib
import os
import select
import signal
import sys
import threading
import time

SIGNALS = (signal.SIGINT, signal.SIGTERM)
EXIT_INTERRUPTED = 130
STUCK_SECONDS = 0.2  # a signal byte left unread this long: the main thread is inside a compiled call


class Interrupted(Exception):
    """Raised by ``Policy.check`` at a safe point once a deferred signal has arrived."""

    def __init__(self, signum: int, detail: str = "nothing was left half-written"):
        self.signum, self.detail = signum, detail  # detail "": the command already said what it kept
        super().__init__(signal.Signals(signum).name)  # "SIGINT", "SIGTERM"


class Policy:
    """Recorded signals, the current mode and the clean-ups run when abandoning."""

    def __init__(self):
        self.received: int | None = None  # the first signal
        self.count = 0
        self.mode = "abandon"
        self._cleanups: list = []
        self._previous: dict = {}
        self._pipe = None  # (read fd, write fd, previous wakeup fd)
        self._acting = threading.RLock()  # reading a byte and recording its signal are one step

    @property
    def requested(self) -> bool:
        return self.received is not None

    @property
    def signal_name(self) -> str:
        return "no signal" if self.received is None else signal.Signals(self.received).name

    def check(self) -> None:
        """Raise ``Interrupted`` when a signal has arrived (call it between compiled calls)."""
        if self.received is not None:
            raise Interrupted(self.received)

    # ------------------------------------------------------------------ modes
    @contextlib.contextmanager
    def defer(self):
        """Signals stop the work at the next ``requested`` check; a second one abandons."""
        with self._mode("defer"):
            yield self

    @contextlib.contextmanager
    def critical(self):
        """Signals are only recorded while the block runs (an output is being written)."""
        with self._mode("critical"):
            yield self

    @contextlib.contextmanager
    def _mode(self, mode: str):
        previous, self.mode = self.mode, mode
        try:
            yield
        finally:
            self.mode = previous

    @contextlib.contextmanager
    def cleanup(self, fn):
        """Run ``fn()`` if the process is abandoned while the block runs."""
        self._cleanups.append(fn)
        try:
            yield
        finally:
            self._cleanups.remove(fn)

    # ------------------------------------------------------------------ acting on signals
    def _signalled(self, data: bytes):
        """Act on delivered signals (one byte each), in the current mode."""
        signum = self._record(data)
        if signum is not None:
            self.abandon(signum)

    def _record(self, data: bytes) -> int | None:
        """Count and record the signals; the one to abandon with where the mode says so."""
        for signum in data:
            self.count += 1
            if self.received is None:
                self.received = signum
            if self.mode == "abandon" or (self.mode == "defer" and self.count > 1):
                return signum
        return None

    def abandon(self, signum: int):
        for fn in reversed(list(self._cleanups)):
            with contextlib.suppress(Exception):  # best effort: the process ends next
                fn()
        with contextlib.suppress(Exception):  # e.g. the signal interrupted a print
            sys.stdout.flush()
        os.write(2, f"jaxsplit: interrupted ({signal.Signals(signum).name})\n".encode())
        os._exit(EXIT_INTERRUPTED)

    def _read(self) -> bytes:
        if self._pipe is None:
            return b""
        try:
            return os.read(self._pipe[0], 64)
        except OSError:  # BlockingIOError: the other reader took the bytes
            return b""

    def _take(self):
        with self._acting:  # a byte read is a signal recorded (``_late_signal`` looks under this lock)
            signum = self._record(self._read())
        if signum is not None:  # outside the lock: abandoning flushes stdout, which may wait for
            self.abandon(signum)  # the main thread, itself in a write whose EINTR ran our handler

    def _late_signal(self) -> int | None:
        """The first signal of the run: recorded, queued but not yet delivered, or delivered with
        its byte still unread (the helper thread reads it and records it under the same lock)."""
        with self._acting:
            pending = set(signal.sigpending()) & set(SIGNALS)
            self._record(self._read())  # critical (``end_process``): recorded only
            return self.received if self.received is not None else min(pending, default=None)

    def _handle(self, signum, frame=None):
        """The Python-level handler (main thread, between bytecodes): act on the bytes now."""
        self._take()

    def _watch(self, read_fd: int, stop_fd: int):
        """Act on signal bytes the main thread has not read within ``STUCK_SECONDS``."""
        while True:
            ready, _, _ = select.select([read_fd, stop_fd], [], [])
            if stop_fd in ready:
                return
            time.sleep(STUCK_SECONDS)
            self._take()

    # ------------------------------------------------------------------ installation
    def install(self):
        if threading.current_thread() is not threading.main_thread():
            return self  # signal handlers can only be set from the main thread
        for sig in SIGNALS:
            previous = signal.getsignal(sig)
            if previous is signal.SIG_IGN:
                continue
            self._previous[sig] = previous
            signal.signal(sig, self._handle)
        if self._previous:
            read_fd, write_fd = os.pipe()
            stop_read, stop_write = os.pipe()
            for fd in (read_fd, write_fd):
                os.set_blocking(fd, False)
            old = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
            self._pipe = (read_fd, write_fd, old, stop_read, stop_write)
            self._watcher = threading.Thread(target=self._watch, args=(read_fd, stop_read), daemon=True,
                                             name="jaxsplit-signals")
            self._watcher.start()
        return self

    def restore(self):
        """Put the previous handlers back."""
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous = {}
        if self._pipe is not None:
            read_fd, write_fd, old, stop_read, stop_write = self._pipe
            signal.set_wakeup_fd(old)
            os.write(stop_write, b"x")
            self._watcher.join()
            self._pipe = None
            for fd in (read_fd, write_fd, stop_read, stop_write):
                os.close(fd)


def end_process(status: int, stop: Policy):
    """End the process now: with ``status``, or 130 when a signal arrived at any moment
    before the status is decided (the documented status of an interrupted run, also for a
    signal that comes after the last output is written). No interpreter teardown follows (a
    signal there was once ignored, turning 130 into 0 in 6 runs of 10).

    The signals stay unblocked in this thread on purpose: the kernel gives a signal sent to
    the process to its main thread whenever that thread accepts it, and there its byte is in
    the wakeup pipe before the next line runs. Blocking them here (as this once did) sent a
    late signal to one of XLA's threads, whose byte could come after the look below (exit 0,
    seen once in CI)."""
    with stop.critical():  # from here a signal is only recorded
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):  # e.g. a closed pipe
                stream.flush()
        late = stop._late_signal()
    if late is not None and status == 0:
        os.write(2, f"jaxsplit: interrupted ({signal.Signals(late).name}) after the work was done; "
                    "every output is complete\n".encode())
        status = EXIT_INTERRUPTED
    os._exit(status)


_CURRENT: list[Policy] = []


@contextlib.contextmanager
def policy():
    """Install the policy for one command-line run (``main``); afterwards restore the handlers."""
    p = Policy().install()
    _CURRENT.append(p)
    try:
        yield p
    finally:
        _CURRENT.pop()
        p.restore()


def current() -> Policy:
    """The policy of the running command (an uninstalled one when called as a library)."""
    return _CURRENT[-1] if _CURRENT else Policy()
