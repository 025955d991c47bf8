"""Acceptance 4 (CLI): a run longer than about 2 s on a terminal shows a progress bar with
steps/s (the scan runs in chunks); ``--quiet`` silences it; no bar when stderr is not a
terminal. The terminal is a real pseudo-terminal (``pty``) for one subprocess run."""

import io
import os
import pty
import select
import subprocess
import sys
import time

import pytest

from jaxsplit.cli import main
from jaxsplit.cli._progress import Progress

# Lie-Trotter runs ~6e6 steps/s on one idle CPU core: 2e7 steps take ~3 s (plus start-up).
LONG_RUN = ["simulate", "--steps", "2e7", "--save-every", "1000", "--no-save"]
MIN_SECONDS = 2.0


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_bar_draws_rate_and_eta_on_a_terminal():
    stream = _Terminal()
    bar = Progress(1000, stream=stream, delay=0.0)
    bar.update(100)
    time.sleep(0.01)
    bar.update(500)
    bar.close(1000)
    text = stream.getvalue()
    assert text.count("\r") == 3 and text.endswith("\n")
    assert "500/1,000 steps" in text and "steps/s" in text and "ETA" in text and "100.0%" in text


@pytest.mark.parametrize("stream,enabled", [(io.StringIO(), None), (_Terminal(), False)],
                         ids=["not-a-terminal", "quiet"])
def test_no_bar_off_terminal_or_when_quiet(stream, enabled):
    bar = Progress(10, stream=stream, enabled=enabled, delay=0.0)
    bar.update(5)
    bar.close(10)
    assert stream.getvalue() == ""


def test_quick_runs_stay_silent():
    stream = _Terminal()
    bar = Progress(10, stream=stream, delay=60.0)
    bar.update(10)
    bar.close(10)
    assert stream.getvalue() == ""


def test_simulate_wires_the_bar_to_stderr_and_quiet(monkeypatch, capsys):
    monkeypatch.setattr("jaxsplit.cli._progress.PROGRESS_DELAY", 0.0)  # draw even for this quick run
    for quiet in (False, True):
        fake = _Terminal()
        monkeypatch.setattr(sys, "stderr", fake)
        assert main(["simulate", "--steps", "1000", "--no-save"] + (["--quiet"] if quiet else [])) == 0
        monkeypatch.setattr(sys, "stderr", sys.__stderr__)
        assert ("steps/s" in fake.getvalue()) is not quiet, fake.getvalue()
    capsys.readouterr()


def test_progress_bar_on_a_real_terminal_run_longer_than_2s():
    master, slave = pty.openpty()
    start = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "jaxsplit.cli", *LONG_RUN], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=slave, close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], 1.0)
        if ready:
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    stdout = proc.communicate(timeout=120)[0].decode()
    seconds = time.monotonic() - start
    os.close(master)
    terminal = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 0, terminal
    assert seconds > MIN_SECONDS
    updates = [part for part in terminal.split("\r") if "steps/s" in part]
    assert len(updates) >= 2, terminal  # redrawn as chunks finish
    assert "20,000,000/20,000,000 steps" in updates[-1] and "ETA" in updates[-1]
    assert "Traceback" not in terminal
    assert "\r" not in stdout and "ETA" not in stdout and "20,000,000 steps" in stdout  # summary stays clean
    print(f"terminal run: {seconds:.1f} s, {len(updates)} bar updates; last: {updates[-1].strip()}")
