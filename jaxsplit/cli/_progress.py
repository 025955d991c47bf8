"""The progress bar of long runs: one line on stderr (done/total, rate, ETA), drawn only on a
terminal, only after ``PROGRESS_DELAY`` seconds (quick runs stay silent), never with --quiet."""

import math
import sys
import time


def _fmt_seconds(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = round(s)
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m:d}:{sec:02d}"


PROGRESS_DELAY = 0.5  # seconds before a bar is drawn: quick runs stay silent


class Progress:
    """A one-line progress bar on stderr: done/total, rate, ETA.

    Drawn only when the stream is a terminal (and ``enabled`` is not False), and only once
    the run has lasted ``delay`` seconds, so quick runs stay silent.
    """

    def __init__(self, total: int, *, unit: str = "steps", stream=None, enabled: bool | None = None,
                 delay: float | None = None, width: int = 24):
        self.total, self.unit, self.width = int(total), unit, width
        self.delay = PROGRESS_DELAY if delay is None else delay
        self.stream = sys.stderr if stream is None else stream
        if enabled is None or enabled:
            try:
                tty = self.stream.isatty()
            except (AttributeError, ValueError):
                tty = False
            enabled = tty if enabled is None else tty and enabled
        self.enabled = bool(enabled)
        self.start = time.perf_counter()
        self.shown = False
        self._first = None  # (time, done) after the first update: rate excludes compilation

    def line(self, done: int, now: float) -> str:
        elapsed = now - self.start
        if self._first is not None and done > self._first[1] and now > self._first[0]:
            rate = (done - self._first[1]) / (now - self._first[0])
        else:
            rate = done / elapsed if elapsed > 0 else float("nan")
        eta = (self.total - done) / rate if rate and rate > 0 else float("nan")
        frac = done / self.total if self.total else 1.0
        filled = round(self.width * frac)
        bar = "#" * filled + "-" * (self.width - filled)
        return (f"[{bar}] {100 * frac:5.1f}%  {done:,}/{self.total:,} {self.unit}  "
                f"{rate:,.0f} {self.unit}/s  elapsed {_fmt_seconds(elapsed)}  ETA {_fmt_seconds(eta)}")

    def update(self, done: int) -> None:
        now = time.perf_counter()
        if self._first is None:
            self._first = (now, done)
        if not self.enabled or (now - self.start < self.delay and not self.shown):
            return
        self.stream.write("\r" + self.line(done, now) + "\x1b[K")
        self.stream.flush()
        self.shown = True

    def close(self, done: int | None = None) -> None:
        if self.shown:
            if done is not None:
                self.stream.write("\r" + self.line(done, time.perf_counter()) + "\x1b[K")
            self.stream.write("\n")
            self.stream.flush()
