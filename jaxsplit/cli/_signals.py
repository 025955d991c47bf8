"""The one signal policy of the command line: SIGINT and SIGTERM are handled alike.

Why the handler never raises: a ``KeyboardInterrupt`` raised into running code unwinds
through JAX while XLA goes on compiling or computing on its own threads, and the
interpreter's teardown then runs under those threads (``fit`` interrupted during
``backend.compile_and_load`` ended in a segmentation fault at exit). So a signal is only
*recorded*, and what happens next depends on the mode of the moment:

* ``abandon`` (the default; nothing finished would be lost: parsing, imports, compiling,
  ``check``, ``fit``, the paper audit): the process ends at once with exit status 130,
  through ``os._exit`` (no teardown racing XLA's threads) after the registered clean-ups
  (lock files, staging directories). A helper thread woken by ``signal.set_wakeup_fd``
  does this even while the main thread waits inside one long compiled call.
* ``defer`` (finished work to keep: the chunks of ``simulate`` and ``sweep``): the command
  looks at ``requested`` between compiled calls, stops, writes what is finished and exits
  130. A second signal abandons.
* ``critical`` (an output being written or the results being printed): only recorded;
  the write completes.

A signal that was ignored when the process started (``nohup``, background jobs) stays
ignored, as Python itself does for SIGINT.
"""

import contextlib
import os
import signal
import sys
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)
EXIT_INTERRUPTED = 130
MODES = ("abandon", "defer", "critical")


class Interrupted(Exception):
    """Raised by ``Policy.check`` at a safe point once a deferred signal has arrived."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


class Policy:
    """Recorded signals, the current mode and the clean-ups run when abandoning."""

    def __init__(self):
        self.received: int | None = None  # the first signal
        self.count = 0
        self.mode = "abandon"
        self._cleanups: list = []
        self._previous: dict = {}
        self._wakeup = None  # (read fd, write fd, previous wakeup fd)

    @property
    def requested(self) -> bool:
        return self.received is not None

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

    # ------------------------------------------------------------------ handling
    def _record(self, signum: int):
        if self.received is None:
            self.received = signum

    def _handle(self, signum, frame=None):
        """The Python-level handler (main thread, between bytecodes)."""
        self._record(signum)
        if self.mode == "abandon":
            self.abandon(signum)

    def abandon(self, signum: int):
        for fn in reversed(list(self._cleanups)):
            with contextlib.suppress(Exception):  # best effort: the process ends next
                fn()
        with contextlib.suppress(Exception):  # e.g. the signal interrupted a print
            sys.stdout.flush()
        os.write(2, f"jaxsplit: interrupted ({signal.Signals(signum).name})\n".encode())
        os._exit(EXIT_INTERRUPTED)

    def _watch(self, read_fd: int):
        """One byte per delivered signal (``set_wakeup_fd``), read even while the main thread
        waits inside a compiled call; the signals are counted here."""
        with open(read_fd, "rb", buffering=0) as pipe:  # closed when the policy is restored
            while data := pipe.read(64):
                self._signalled(data)

    def _signalled(self, data: bytes):
        for signum in data:
            self.count += 1
            self._record(signum)
            if self.mode == "abandon" or (self.mode == "defer" and self.count > 1):
                self.abandon(signum)

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
            os.set_blocking(write_fd, False)
            old = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
            self._wakeup = (read_fd, write_fd, old)
            threading.Thread(target=self._watch, args=(read_fd,), daemon=True, name="jaxsplit-signals").start()
        return self

    def restore(self):
        if self._wakeup is not None:
            _, write_fd, old = self._wakeup
            signal.set_wakeup_fd(old)
            os.close(write_fd)  # the watcher reads end-of-file and returns
            self._wakeup = None
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous = {}


_CURRENT: list[Policy] = []


@contextlib.contextmanager
def policy():
    """Install the policy for one command-line run (``main``) and restore the handlers after."""
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
