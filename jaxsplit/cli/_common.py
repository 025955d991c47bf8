"""Shared pieces of the subcommands: argument types, output paths, progress, chunked runs.

Conventions every subcommand follows:

* bad input raises ``InputError`` (or an argparse error) -> one line on stderr, exit 2;
* outputs are written atomically (temporary file + ``os.replace``) and never overwrite an
  existing file unless ``--force``;
* a progress bar goes to stderr only when stderr is a terminal and ``--quiet`` is not set;
* ``--json`` prints one JSON object on stdout (non-finite numbers become ``null``).
"""

import argparse
import json
import math
import os
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..core._errors import InputError

EXIT_OK = 0
EXIT_INPUT = 2
EXIT_NONFINITE = 3
EXIT_INTERRUPTED = 130

EXIT_CODES_HELP = (
    "exit status: 0 success; 2 bad input (one line on stderr, nothing run); "
    "3 the state became non-finite (what was computed is kept); 130 interrupted (Ctrl-C)"
)


# --------------------------------------------------------------------------- argument types


def _number(text: str, name: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number ({name})") from None


def vector3(name: str, what: str = "a,b,c"):
    """argparse type: three comma-separated finite numbers."""

    def parse(text: str):
        parts = [p.strip() for p in str(text).split(",")]
        if len(parts) != 3 or any(p == "" for p in parts):
            raise argparse.ArgumentTypeError(
                f"needs 3 comma-separated numbers {what}, got {text!r} ({len(parts)} value"
                f"{'s' if len(parts) != 1 else ''})"
            )
        values = tuple(_number(p, name) for p in parts)
        if not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"must be finite numbers, got {text!r}")
        return values

    return parse


def positive_int(text) -> int:
    """argparse type: an integer >= 1; accepts 10000, 10_000 and 1e4."""
    s = str(text).strip().replace("_", "")
    try:
        value = int(s)
    except ValueError:
        try:
            f = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
        if not (math.isfinite(f) and f == int(f)):
            raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
        value = int(f)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer (>= 1), got {text!r}")
    return value


def nonzero_float(text) -> float:
    """argparse type: a finite, non-zero number (a step size; negative integrates backwards)."""
    value = _number(text, "step size")
    if not math.isfinite(value) or value == 0:
        raise argparse.ArgumentTypeError(f"must be a finite non-zero number, got {text!r}")
    return value


def positive_float(text) -> float:
    value = _number(text, "positive number")
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite positive number, got {text!r}")
    return value


_SIZE = re.compile(r"^\s*([0-9.]+(?:e[+-]?\d+)?)\s*([kmgt]?)i?b?\s*$", re.IGNORECASE)


def byte_size(text) -> int:
    """argparse type: a memory size such as 500M, 2G, 1.5GiB or a plain byte count."""
    match = _SIZE.match(str(text))
    if not match:
        raise argparse.ArgumentTypeError(f"must be a size like 500M or 2G, got {text!r}")
    try:
        value = float(match.group(1)) * 1024 ** " kmgt".index(match.group(2).lower() or " ")
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a size like 500M or 2G, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive size, got {text!r}")
    return int(value)


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def add_common_flags(p, *, outputs=True, json_flag=True, quiet=True):
    if outputs:
        p.add_argument("--force", action="store_true", help="overwrite existing output files")
    if json_flag:
        p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    if quiet:
        p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")


def check_body(inertia, allow_nonphysical: bool):
    """A RigidBody from a parsed --inertia, refusing non-physical bodies unless allowed."""
    import jax.numpy as jnp

    from ..systems._rigid_body import RigidBody

    if not all(v > 0 for v in inertia):
        raise InputError(f"--inertia must be positive (I1,I2,I3 > 0), got {fmt_vec(inertia)}")
    body = RigidBody(jnp.asarray(inertia, dtype=jnp.float64))
    if not allow_nonphysical and not body.is_physical():
        i = inertia
        for a, b, c, names in ((0, 1, 2, "I1 + I2 >= I3"), (1, 2, 0, "I2 + I3 >= I1"), (2, 0, 1, "I3 + I1 >= I2")):
            if i[a] + i[b] < i[c]:
                failed = f"{names} fails ({i[a]:g} + {i[b]:g} < {i[c]:g})"
                break
        raise InputError(
            f"--inertia {fmt_vec(inertia)} is not a physical body: triangle inequality {failed}; "
            "pass --allow-nonphysical to integrate it anyway"
        )
    return body


def fmt_vec(v) -> str:
    return ",".join(f"{float(x):g}" for x in v)


# --------------------------------------------------------------------------- output files


def check_output(path, force: bool, what: str = "output") -> Path:
    """Validate an output path before any work is done; returns it as a Path."""
    p = Path(path).expanduser()
    if p.is_dir():
        raise InputError(f"{what} path {str(p)!r} is a directory; give a file name")
    if (p.exists() or p.is_symlink()) and not force:
        raise InputError(f"{what} file {str(p)!r} exists; pass --force to overwrite it or choose another path")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise InputError(f"cannot write {what} {str(p)!r}: directory {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise InputError(f"cannot write {what} {str(p)!r}: {str(parent)!r} is not a directory")
    try:  # os.access is unreliable (root, read-only mounts): really try
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{p.name}.", suffix=".probe")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise InputError(f"cannot write {what} {str(p)!r}: {err.strerror or err}") from None
    return p


def atomic_write(path: Path, write) -> Path:
    """``write(fileobj)`` into a temporary file next to ``path``, then rename over it."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.",
                               suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def save_npz(path: Path, arrays: dict) -> Path:
    return atomic_write(path, lambda f: np.savez(f, **arrays))


def metadata_array(meta: dict) -> np.ndarray:
    """Metadata stored inside an ``.npz`` as a JSON string (loads without pickle)."""
    return np.array(json.dumps(jsonable(meta)))


def read_metadata(npz) -> dict:
    return json.loads(str(npz["metadata"]))


def run_metadata(command: str, argv=None) -> dict:
    import platform

    import jax

    from .. import __version__

    return {
        "command": command,
        "argv": list(sys.argv[1:] if argv is None else argv),
        "jaxsplit_version": __version__,
        "jax_version": jax.__version__,
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "dtype": "float64",
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


# --------------------------------------------------------------------------- JSON


def jsonable(obj):
    """Plain JSON types; non-finite floats become None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def print_json(obj) -> None:
    print(json.dumps(jsonable(obj), allow_nan=False))


# --------------------------------------------------------------------------- memory


def available_memory() -> int:
    """Bytes of memory available now (MemAvailable on Linux; total memory otherwise)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 * 1024**3


def default_memory_limit() -> int:
    """Half of the memory available now."""
    return available_memory() // 2


def check_memory(n_saved: int, bytes_per_saved: int, limit: int, *, steps: int, save_every: int,
                 option: str = "--save-every"):
    """Refuse (InputError) before running when the saved states would not fit in ``limit``."""
    need = n_saved * bytes_per_saved
    if need <= limit:
        return need
    suggest = max(save_every + 1, math.ceil(steps * bytes_per_saved / (0.5 * limit)))
    raise InputError(
        f"the trajectory would need about {format_bytes(need)} of memory ({n_saved:,} saved states) "
        f"but the limit is {format_bytes(limit)} (--max-memory); save fewer states, e.g. "
        f"{option} {suggest}"
    )


# --------------------------------------------------------------------------- progress


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


# --------------------------------------------------------------------------- chunked runs

TARGET_FLOWS_PER_CHUNK = 1_000_000  # ~0.05-0.4 s of work per chunk on a CPU core


class RunResult(NamedTuple):
    """Saved states of a chunked run: ``x[i]`` after ``steps[i]`` steps."""

    steps: np.ndarray
    x: np.ndarray
    completed: int  # steps completed with a finite state
    nonfinite_step: int | None  # first step whose state is not finite
    interrupted: bool
    seconds: float


def chunk_size(n_steps: int, save_every: int, flows_per_step: int = 1,
               target_flows: int | None = None) -> int:
    """Steps per chunk doing about ``target_flows`` flows: a multiple of ``save_every`` when
    states are saved that often, else a plain step count (saves then fall on chunk ends)."""
    target_flows = TARGET_FLOWS_PER_CHUNK if target_flows is None else target_flows
    per = max(1, target_flows // max(1, flows_per_step))
    if save_every > per:
        return min(per, n_steps)
    chunk = (per // save_every) * save_every
    return min(chunk, max(save_every, -(-n_steps // save_every) * save_every))


def _finite_rows(x: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(x.reshape(len(x), -1)), axis=1) if len(x) else np.ones(0, bool)


def first_nonfinite(step, x, h, n: int) -> tuple[int, np.ndarray]:
    """Within ``n`` steps from the finite state ``x``: (first step k >= 1 whose state is not
    finite, the state after k - 1 steps). Narrows down by blocks, 1024 saves at a time."""
    from ..core._integrate import integrate

    offset = 0
    while True:
        block = max(1, -(-n // 1024))
        traj = integrate(step, x, h, n, save_every=block)
        xs = np.asarray(traj.x)
        counts = np.minimum(np.arange(len(xs)) * block, n)
        bad = np.flatnonzero(~_finite_rows(xs))
        if len(bad) == 0:  # round-off differences between runs: treat the last step as bad
            return offset + n, xs[-1]
        i = int(bad[0])
        if block == 1:
            return offset + int(counts[i]), xs[i - 1]
        offset += int(counts[i - 1])
        n = int(counts[i] - counts[i - 1])
        x = traj.x[i - 1]


def run_chunked(step, x0, h, n_steps: int, save_every: int, *, flows_per_step: int = 1,
                chunk: int | None = None, progress: Progress | None = None) -> RunResult:
    """Integrate in chunks of equal size (the compiled scan is reused), checking after each
    chunk that the state is finite. Saves ``x0``, every ``save_every``-th state and the last
    one, like ``integrate(..., save_every=...)``. A non-finite state stops the run at the
    first bad step; Ctrl-C stops it after the current chunk; either way the states computed
    so far are returned (with the last good state)."""
    import jax.numpy as jnp

    from ..core._integrate import integrate

    chunk = chunk or chunk_size(n_steps, save_every, flows_per_step)
    aligned = chunk % save_every == 0  # else save_every > chunk: saves fall on chunk ends
    start = time.perf_counter()
    x = jnp.asarray(x0)
    steps, saved = [np.zeros(1, dtype=np.int64)], [np.asarray(x)[None]]
    done, nonfinite, interrupted = 0, None, False

    def last_saved():
        return int(steps[-1][-1]) if len(steps[-1]) else int(np.concatenate(steps)[-1])

    try:
        while done < n_steps:
            if aligned:
                n = min(chunk, n_steps - done)
                traj = integrate(step, x, h, n, save_every=save_every)
                xs = np.asarray(traj.x)[1:]
                local = np.arange(1, len(xs) + 1, dtype=np.int64) * save_every
                local[-1] = n
                x_end = traj.x[-1]
            else:
                next_save = (done // save_every + 1) * save_every
                n = min(chunk, next_save - done, n_steps - done)
                x_end = integrate(step, x, h, n).final
                is_save = done + n == next_save or done + n == n_steps
                xs = np.asarray(x_end)[None]
                local = np.array([n], dtype=np.int64)
                if not np.all(np.isfinite(xs)):
                    is_save = True  # handled below
                if not is_save:
                    xs, local = xs[:0], local[:0]
            if not _finite_rows(xs).all():
                bad, last = first_nonfinite(step, x, h, n)
                keep = local < bad
                steps.append(done + local[keep])
                saved.append(xs[keep])
                if done + bad - 1 > last_saved():
                    steps.append(np.array([done + bad - 1]))
                    saved.append(np.asarray(last)[None])
                nonfinite = done + bad
                done += bad - 1
                break
            steps.append(done + local)
            saved.append(xs)
            x = x_end
            done += n
            if progress is not None:
                progress.update(done)
    except KeyboardInterrupt:
        interrupted = True
        if done > last_saved():  # keep the last state reached
            steps.append(np.array([done]))
            saved.append(np.asarray(x)[None])
    finally:
        if progress is not None:
            progress.close(done if not interrupted else None)
    return RunResult(np.concatenate(steps), np.concatenate(saved), done, nonfinite, interrupted,
                     time.perf_counter() - start)


def resolve_scheme_and_shift(args, body):
    """The scheme named by ``--scheme`` and the Casimir shift axis as the CLI labels it,
    1, 2 or 3 like I1, I2, I3 (``None`` for the axes split; the library's ``shift`` is this
    minus one), refusing a scheme that does not fit ``--split`` and a stray ``--shift-axis``."""
    from ..core._schemes import schemes

    scheme = schemes[args.scheme]
    if not scheme.pieces_allowed(3 if args.split == "axes" else 2):
        raise InputError(f"--scheme {scheme.name} is {scheme.form} (exactly two pieces) and does not fit "
                         "--split axes (three pieces); use --split casimir")
    if args.shift_axis is not None and args.split != "casimir":
        raise InputError("--shift-axis applies only with --split casimir")
    shift = "auto" if args.shift_axis in (None, "auto") else int(args.shift_axis)
    if args.split == "casimir" and shift == "auto":
        shift = body.shift_axis("auto") + 1
    return scheme, shift


def split_options(split: str, shift) -> dict:
    """The library's split options from the CLI's 1-based ``--shift-axis`` label."""
    return {"shift": int(shift) - 1} if split == "casimir" else {}
