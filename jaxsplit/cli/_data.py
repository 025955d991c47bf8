"""The one trajectory data format of the command line: what ``simulate`` writes and ``fit``
reads, as ``.npz`` or ``.csv`` (the same arrays either way).

Arrays, one row per saved state (leading axis n):

* ``t`` (n,) the times; ``step`` (n,) the step count of each grid state (absent when the
  rows are the ``--save-at`` times, which fall between steps);
* the state: ``m`` (n, 3), with ``Q`` (n, 3, 3) for the attitude or ``gamma`` (n, 3) for
  the heavy top and the gravity-gradient satellite;
* the scalar invariants at each state: ``energy``, ``casimir``, ``gamma_norm_sq``,
  ``m_dot_gamma``, ``m_norm_sq`` (as the system has them);
* ``m_exact`` (and ``Q_exact``): the exact solution at t (the free body);
* ``metadata``: one JSON object (every input, versions, dtype, status, noise).

A ``.csv`` starts with ``# metadata: {json}``, then the column names (``# t,m1,m2,m3,...``):
an array (n, 3) is three columns ``name1..name3``, an array (n, 3, 3) nine columns
``name11..name33``. ``read`` returns the arrays and the metadata of either format; a CSV
from elsewhere needs only a line of column names (``t,m1,m2,m3``, ``#`` optional). A file
that is not a regular file (a directory, a FIFO, a device) is refused before it is opened.
"""

import json
import os
import re
import zipfile

import numpy as np

from ..core._errors import InputError
from . import _metadata

FORMATS = ("npz", "csv")
MAX_CSV_BYTES = 2**30  # a CSV is parsed in memory (several times its size)


def write(outputs, path, fmt: str, arrays: dict, meta: dict) -> None:
    """``arrays`` (each with the leading axis n) and ``meta`` to ``path`` through the one writer."""
    if fmt == "npz":
        outputs.write_npz(path, arrays | {"metadata": _metadata.metadata_array(meta)})
        return
    columns = []
    for name, a in arrays.items():
        a = np.asarray(a)
        if a.ndim == 1:
            columns.append((name, a))
        else:
            flat = a.reshape(len(a), -1)
            labels = ["".join(str(i + 1) for i in np.unravel_index(k, a.shape[1:])) for k in range(flat.shape[1])]
            columns += [(f"{name}{label}", flat[:, k]) for k, label in enumerate(labels)]
    header = "metadata: " + json.dumps(_metadata.jsonable(meta)) + "\n" + ",".join(name for name, _ in columns)
    data = np.column_stack([np.asarray(v, dtype=np.float64) for _, v in columns])
    fmts = ["%d" if np.issubdtype(np.asarray(v).dtype, np.integer) else "%.17g" for _, v in columns]
    outputs.write(path, lambda f: np.savetxt(f, data, delimiter=",", header=header, fmt=fmts, comments="# "))


def read(path: str) -> tuple[dict, dict]:
    """(arrays, metadata) of a trajectory file (.npz or .csv); malformed -> one-line InputError."""
    kind = _kind(path)
    return _read_csv(path) if kind == "csv" else _read_npz(path)


def _kind(path: str) -> str:
    if not os.path.exists(path):
        raise InputError(f"no such data file: {path}")
    suffix = os.path.splitext(path)[1].lower()
    kind = "csv" if suffix == ".csv" else "npz"
    if not os.path.isfile(path):
        what = "a directory" if os.path.isdir(path) else "not a regular file"
        raise InputError(f"{path} is not a readable .{kind} file ({what})")
    if suffix not in (".csv", ".npz"):  # sniff: a zip (.npz) or a NumPy array starts with magic bytes
        with open(path, "rb") as f:
            head = f.read(6)
        kind = "npz" if head.startswith((b"PK", b"\x93NUMPY")) else "csv"
    return kind


def _read_npz(path: str) -> tuple[dict, dict]:
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise InputError(f"{path} is not a readable .npz file ({type(err).__name__})") from err
    if not isinstance(data, np.lib.npyio.NpzFile):  # an .npy file: one bare array
        raise InputError(f"{path} holds a single array (.npy); expected an .npz holding t (n,) and m (n, 3)")
    try:
        with data:
            arrays = {k: np.asarray(data[k]) for k in data.files if k != "metadata"}
            meta = _metadata.read_metadata(data) if "metadata" in data.files else {}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise InputError(f"{path} is not a readable .npz file ({type(err).__name__})") from err
    return arrays, meta if isinstance(meta, dict) else {}


_METADATA = "# metadata:"


def _read_csv(path: str) -> tuple[dict, dict]:
    size = os.path.getsize(path)
    if size > MAX_CSV_BYTES:
        raise InputError(f"{path} is {size:,} bytes, more than the {MAX_CSV_BYTES:,} a CSV may have (it is parsed in "
                         "memory); convert it to .npz")
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path} is not a readable .csv file ({type(err).__name__})") from None
    meta, k = {}, 0
    if lines and lines[0].startswith(_METADATA):
        try:
            meta = json.loads(lines[0][len(_METADATA):])
        except ValueError:
            raise InputError(f"{path}: line 1 is not '# metadata: <JSON object>'") from None
        k = 1
    while k < len(lines) and not lines[k].strip():
        k += 1
    if k == len(lines):
        raise InputError(f"{path} holds no column names (a first line such as 't,m1,m2,m3')")
    names = [n.strip() for n in lines[k].lstrip("#").split(",")]
    if not all(re.fullmatch(r"[A-Za-z_]\w*", n) for n in names) or len(set(names)) != len(names):
        raise InputError(f"{path}: line {k + 1} must name the columns (distinct names such as t,m1,m2,m3), "
                         f"got {lines[k][:60]!r}")
    table = []
    for j, line in enumerate(lines[k + 1:], start=k + 2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = line.split(",")
        if len(cells) != len(names):
            raise InputError(f"{path}: line {j} has {len(cells)} values, the header names {len(names)} columns")
        try:
            table.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise InputError(f"{path}: line {j}: {bad.strip()[:30]!r} is not a number") from None
    data = np.asarray(table, dtype=np.float64).reshape(len(table), len(names))
    return _group_columns(dict(zip(names, data.T))), meta if isinstance(meta, dict) else {}


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _group_columns(columns: dict) -> dict:
    """name1..name3 -> name (n, 3); name11..name33 -> name (n, 3, 3); the rest as they are."""
    out, used = {}, set()
    for name in columns:
        base = re.sub(r"\d+$", "", name)
        if not base or base in out:
            continue
        matrix = [f"{base}{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
        vector = [f"{base}{i}" for i in (1, 2, 3)]
        for keys, shape in ((matrix, (3, 3)), (vector, (3,))):
            if all(k in columns for k in keys) and not used & set(keys):
                out[base] = np.stack([columns[k] for k in keys], axis=1).reshape((-1,) + shape)
                used |= set(keys)
                break
    for name, values in columns.items():
        if name not in used:
            out.setdefault(name, values)
    return out
