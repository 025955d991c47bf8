"""The one writer of the command line: every output file goes through ``Outputs``.

A command *claims* its outputs before any work: each path is resolved
(``Path.resolve()``: ``a/../run.npz``, ``./run.npz`` and a symlink to it are one file),
compared with the command's other outputs by that resolved file (and by inode for hard
links), checked (a regular file, a symlink or nothing; no overwriting without ``--force``;
a name the file system accepts; a writable directory) and *locked* (``flock`` on a lock file
next to it, or inside an output directory), so a second run into the same output exits
with status 2 instead of mixing its numbers with the first one's. Writing is atomic (a
temporary file in the same directory, ``fsync``, ``os.replace`` onto the output's
own name: a symlink there is replaced, never written through into its target) and runs
in the signal policy's ``critical`` mode, so a file is complete or absent, never half-written. Locks
and temporary files are removed when the command ends, also when it is abandoned.

Under the launcher (``python -m jaxsplit.launch -n N -- simulate ...``) every process runs
the whole command and only process 0 writes: in the others a claim checks the path's name and
returns it (no lock, no test of an existing file: process 0 owns both), and a write is
skipped (``distributed.process_index``).
"""

import contextlib
import fcntl
import hashlib
import json
import os
import stat
import tempfile
from pathlib import Path

import numpy as np

from .. import distributed
from ..core._errors import InputError
from . import _signals
from ._metadata import jsonable

DIRECTORY_LOCK = ".jaxsplit-lock"
TEMP_PREFIX = ".jaxsplit-"
TEMP_SUFFIX = ".tmp"


class OutputBusy(InputError):
    """The output is locked by another running command."""


def _name_max(directory: Path) -> int:
    while not os.path.isdir(directory) and directory != directory.parent:
        directory = directory.parent
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def resolve(path, what: str) -> Path:
    """``path`` made absolute with symlinks resolved, every name in it checked for length
    (a name too long for the file system would fail every probe with an OSError)."""
    text = os.fspath(path)
    if text == "" or "\0" in text:
        raise InputError(f"{what} path {text!r} is not a file name")
    try:
        p = Path(text).expanduser().resolve()
    except (OSError, RuntimeError) as err:  # a symlink loop
        raise InputError(f"{what} path {text!r} cannot be resolved ({err})") from None
    limit = _name_max(p.parent)
    for name in p.parts:
        if len(os.fsencode(name)) > limit:
            raise InputError(f"{what} {text[:40]!r}...: a name in it is {len(os.fsencode(name))} bytes long; the file "
                             f"system allows {limit}")
    return p


class Outputs:
    """The outputs of one command run: claimed up front, written atomically, locked until closed."""

    def __init__(self, force: bool = False):
        self.force = force
        self.writes = distributed.process_index() == 0  # several processes: process 0 writes
        self._files: dict[Path, str] = {}
        self._dirs: dict[Path, str] = {}
        self._locks: list[tuple[int, Path]] = []
        self._temporaries: set[str] = set()
        self._stack = contextlib.ExitStack()

    def __enter__(self):
        self._stack.enter_context(_signals.current().cleanup(self._abandoned))
        return self

    def __exit__(self, *exc):
        self.close()
        self._stack.close()
        return False

    # ------------------------------------------------------------------ claims
    def file(self, path, what: str, *, force: bool | None = None) -> Path:
        """Claim an output file: distinct from the other outputs, writable, locked, and not
        existing unless ``force`` (default: the command's ``--force``). Returns the name to
        write: its directory resolved, its last name kept, so that a symlink there is
        replaced by the output, never written through into the file it points to."""
        force = self.force if force is None else force
        shown = os.fspath(path)
        p = resolve(path, what)  # the file the name reaches now: compared with the other outputs
        given = Path(shown).expanduser()
        if not self.writes:  # another process of the run: process 0 claims and writes
            return resolve(given.parent, what) / given.name
        if os.path.isdir(p) or shown.endswith(("/", os.sep)) or given.name in ("", ".", ".."):
            raise InputError(f"{what} path {shown!r} is a directory; give a file name")
        for other, other_what in self._files.items():
            reached = other.resolve()
            if reached == p or (os.path.exists(p) and os.path.exists(reached) and os.path.samefile(reached, p)):
                raise InputError(f"{what} {shown!r} is the same file as the {other_what} ({str(other)!r}); "
                                 "give them different names")
        parent = resolve(given.parent, what)
        if not os.path.exists(parent):
            raise InputError(f"cannot write {what} {shown!r}: directory {str(parent)!r} does not exist")
        if not os.path.isdir(parent):
            raise InputError(f"cannot write {what} {shown!r}: {str(parent)!r} is not a directory")
        target = parent / given.name
        if parent not in self._dirs:  # a claimed directory's lock already covers its files
            lock = parent / f"{TEMP_PREFIX}lock-{hashlib.sha256(os.fsencode(target.name)).hexdigest()[:16]}"
            self._lock(lock, f"{what} {shown!r}")
        if os.path.lexists(target) and not force:
            raise InputError(f"{what} file {shown!r} exists; pass --force to overwrite it or choose another path")
        if os.path.lexists(target) and not (stat.S_ISREG(os.lstat(target).st_mode) or os.path.islink(target)):
            raise InputError(f"{what} {shown!r} exists and is not a regular file; it is never replaced")
        self._files[target] = what
        return target

    def directory(self, path, what: str, *, resume: bool = False) -> Path:
        """Claim an output directory (created if missing; with ``resume`` it must exist) and
        lock it: the files inside it are the command's to write."""
        shown = os.fspath(path)
        p = resolve(path, what)
        if not self.writes:
            return p
        if resume and not os.path.isdir(p):
            raise InputError(f"nothing to resume: {what} {shown!r} does not exist; run without --resume to start")
        if os.path.exists(p) and not os.path.isdir(p):
            raise InputError(f"{what} {shown!r} exists and is not a directory")
        for other, other_what in self._dirs.items():
            if other == p:
                raise InputError(f"{what} {shown!r} is the same directory as the {other_what}")
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"cannot create {what} {shown!r}: {err.strerror or err}") from None
        self._lock(p / DIRECTORY_LOCK, f"{what} {shown!r}")
        self._dirs[p] = what
        return p

    def _lock(self, lock: Path, what: str) -> None:
        """flock(2) on ``lock``; held until ``close``. A lock file unlinked by its previous
        holder between our open and our flock is a stale inode: open again."""
        while True:
            try:
                fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except OSError as err:
                raise InputError(f"cannot write {what}: {err.strerror or err}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
                os.close(fd)
                raise OutputBusy(f"{what} is in use by another jaxsplit run"
                                 + (f" (pid {holder})" if holder.isdigit() else "")
                                 + "; wait for it to finish or choose another output") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(lock))
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.pwrite(fd, str(os.getpid()).encode(), 0)
                self._locks.append((fd, lock))
                return
            os.close(fd)

    def claimed(self) -> set[Path]:
        return set(self._files)

    # ------------------------------------------------------------------ writing
    def _check_claimed(self, path: Path) -> Path:
        p = Path(path).parent.resolve() / Path(path).name  # a symlink as the last name is replaced, not followed
        if p not in self._files and p.parent not in self._dirs:
            raise RuntimeError(f"{p} was not claimed before writing")  # a bug, not bad input
        return p

    def write(self, path, write) -> Path:
        """``write(binary file)`` into a temporary file next to ``path``, then rename over it
        (in process 0 only: the others return the path and write nothing)."""
        if not self.writes:
            return Path(path)
        p = self._check_claimed(path)
        with _signals.current().critical():
            fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX)
            self._temporaries.add(tmp)
            try:
                os.fchmod(fd, 0o666 & ~_umask())
                with os.fdopen(fd, "wb") as f:
                    write(f)
                    f.flush()
                    os.fsync(f.fileno())
                os.replace(tmp, p)
                _fsync_directory(p.parent)
            except OSError as err:
                raise InputError(f"cannot write {p}: {err.strerror or err}") from None
            finally:
                self._temporaries.discard(tmp)
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(tmp)
        return p

    def write_bytes(self, path, data: bytes) -> Path:
        return self.write(path, lambda f: f.write(data))

    def write_json(self, path, obj) -> Path:
        return self.write_bytes(path, (json.dumps(jsonable(obj), indent=2) + "\n").encode())

    def write_npz(self, path, arrays: dict) -> Path:
        return self.write(path, lambda f: np.savez(f, **arrays))

    def remove_temporaries(self, directory: Path) -> None:
        """Temporary files a killed run left in a claimed directory (we hold its lock)."""
        if not self.writes:
            return
        for stale in Path(directory).glob(f"{TEMP_PREFIX}*{TEMP_SUFFIX}"):
            stale.unlink(missing_ok=True)

    # ------------------------------------------------------------------ release
    def close(self) -> None:
        for fd, lock in reversed(self._locks):
            with contextlib.suppress(OSError):
                os.unlink(lock)  # while still held: the next holder opens a fresh file
            with contextlib.suppress(OSError):
                os.close(fd)
        self._locks = []

    def _abandoned(self) -> None:
        for tmp in list(self._temporaries):
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self.close()


def _fsync_directory(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask
