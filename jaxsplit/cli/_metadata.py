"""What a run records about itself: metadata (inputs, versions, dtype, time) stored with
its arrays, and JSON on stdout (non-finite numbers become ``null``, never invalid JSON)."""

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np


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
        "xla_flags": os.environ.get("XLA_FLAGS", ""),  # results are bit-reproducible per flag set
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
