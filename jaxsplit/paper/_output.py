"""The only place the paper audit touches the file system: ``check_out_dir`` validates the
output directory before the run (it writes nothing) and ``write_outputs`` writes every file
after it. To be routed through the CLI's single atomic writer (with its lock): replace the
body of ``write_outputs``.
"""

import os

from ..core._errors import InputError

MARKER = "claims.json"  # written last: its presence means a complete audit


def check_out_dir(out_dir, force: bool) -> str:
    """The output directory as a path, refused before any work if it cannot receive the audit."""
    out_dir = os.fspath(out_dir)
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise InputError(f"--out {out_dir!r} exists and is not a directory")
    if os.path.exists(os.path.join(out_dir, MARKER)) and not force:
        raise InputError(f"{out_dir!r} already holds {MARKER}; use --force to overwrite")
    existing = os.path.abspath(out_dir)
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing) or not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"cannot write --out {out_dir!r}: {existing!r} is not a writable directory")
    return out_dir


def write_outputs(out_dir: str, files: dict) -> None:
    """Write {file name: bytes} into ``out_dir`` (created if missing), in the given order, each
    file atomically (a temporary file, then ``os.replace``)."""
    os.makedirs(out_dir, exist_ok=True)
    for name, data in files.items():
        path = os.path.join(out_dir, name)
        with open(path + ".tmp", "wb") as fh:
            fh.write(data)
        os.replace(path + ".tmp", path)
