"""Native CPU kernels, compiled on first use with the machine's C++ compiler.

XLA's CPU emitter forms no multi-output fusion: a spin pair's flow (``systems/_spin_pairs.py``)
writes six new components and XLA evaluated the pair's sum, polynomials and cross products once
per component. ``systems/_pair_kernel.cc`` evaluates them once, as an XLA FFI custom call.

It is built the first time a program needs it (never on import): ``$CXX`` or ``c++`` with
``-O3 -march=native`` against the headers jaxlib ships (``jax.ffi.include_dir()``), into
``$JAXSPLIT_CACHE`` (default ``~/.cache/jaxsplit``), keyed by the source, the flags, jaxlib's
version and the machine, written atomically (processes may race). Where it cannot be built or
loaded (no compiler, a failed build, a damaged cached library) the XLA path runs, the same maps to
round-off, and ``native_status()`` says why (one warning when a build or a load fails). ``JAXSPLIT_NATIVE=0`` turns it off (read once, at the
first program that asks). Only on a CPU backend with one device: a custom call is opaque to XLA's
partitioner, so sharded programs keep the XLA path (``distributed``).
"""

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import jax

SOURCE = Path(__file__).parent / "systems" / "_pair_kernel.cc"
TARGET = "jaxsplit_pair_flow"
FLAGS = ("-O3", "-march=native", "-std=c++17", "-shared", "-fPIC", "-w")
_STATUS = {"pair flow": "not asked for yet"}


def native_status() -> dict:
    """{kernel: "native (path)" or the reason it is not}: what the last programs ran."""
    return dict(_STATUS)


def _cache_dir() -> Path:
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "jaxsplit"
    return Path(os.environ.get("JAXSPLIT_CACHE", default))


def _machine() -> str:
    try:
        model = next(line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("model name"))
    except (OSError, StopIteration):
        model = ""
    return f"{platform.machine()} {platform.node()} {model}"


@functools.cache
def _library() -> str | None:
    """The built kernel's path, or None (the reason in ``_STATUS``)."""
    if os.environ.get("JAXSPLIT_NATIVE", "1") == "0":
        _STATUS["pair flow"] = "off (JAXSPLIT_NATIVE=0)"
        return None
    compiler = os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if not compiler:
        _STATUS["pair flow"] = "no C++ compiler found (set CXX): the XLA path runs"
        return None
    source = SOURCE.read_bytes()
    key = hashlib.sha256(b"\0".join([source, " ".join(FLAGS).encode(), compiler.encode(),
                                     jax.lib.__version__.encode(), _machine().encode()])).hexdigest()[:16]
    path = _cache_dir() / f"pair_kernel-{key}.so"
    if not path.exists():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
                built = Path(tmp) / path.name
                subprocess.run([compiler, *FLAGS, f"-I{jax.ffi.include_dir()}", str(SOURCE), "-o", str(built)],
                               check=True, capture_output=True, text=True, timeout=300)
                os.replace(built, path)  # atomic: a racing process finds a whole library or none
        except (OSError, subprocess.SubprocessError) as err:
            lines = (getattr(err, "stderr", "") or str(err)).strip().splitlines() or [repr(err)]
            _STATUS["pair flow"] = f"build failed ({compiler}): {next((l for l in lines if 'error' in l), lines[0])}"
            warnings.warn(f"jaxsplit: the native pair kernel was not built, the XLA path runs: {_STATUS['pair flow']}",
                          RuntimeWarning, stacklevel=3)
            return None
    _STATUS["pair flow"] = f"native ({path})"
    return str(path)


@functools.cache
def _registered() -> bool:
    path = _library()
    if path is None:
        return False
    try:
        library = ctypes.cdll.LoadLibrary(path)
    except OSError as err:  # a library another machine or a damaged disk left in the cache
        _STATUS["pair flow"] = f"could not load {path}: {err}"
        warnings.warn(f"jaxsplit: the native pair kernel was not loaded, the XLA path runs: {_STATUS['pair flow']} "
                      "(delete the file to rebuild it)", RuntimeWarning, stacklevel=3)
        return False
    jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(library.JaxsplitPairFlow), platform="cpu")
    return True


def pair_kernel_available(dtype) -> bool:
    """Whether a program traced now may call the native pair kernel for ``dtype``."""
    if jax.numpy.dtype(dtype).name not in ("float32", "float64"):
        return False
    if jax.default_backend() != "cpu" or jax.device_count() != 1:
        return False
    return _registered()
