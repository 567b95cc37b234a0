"""CasADi functions compiled to native code and called through ``ctypes`` with numpy buffers bound once.

A 14-joint IK step is a few thousand floating-point operations; evaluated as numpy calls it costs tens of
microseconds of interpreter overhead, and a CasADi ``Function`` called from Python costs ~35 µs of argument
conversion alone. CasADi's C code generator, compiled once per kernel by the system's C compiler, runs the same
expression graph in a few microseconds, and a ``ctypes`` call with pre-built pointer arrays adds under 1 µs.

Compiled libraries are cached in ``$TAPLAN_CACHE`` (default ``~/.cache/taplan``) under a hash of their C source, so
a kernel is compiled once per machine. Without a working C compiler (``$CC``, else ``cc``/``gcc``/``clang``) or with
``TAPLAN_NATIVE=0``, :func:`compile_function` returns None and callers keep their numpy path.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["NativeFunction", "compile_function", "native_enabled"]

_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_FLAGS = ("-O2", "-shared", "-fPIC")
_loaded: dict[str, ctypes.CDLL] = {}  # by source digest
_by_function: dict[int, tuple[ca.Function, ctypes.CDLL]] = {}  # by function identity: no code generation again


def native_enabled() -> bool:
    """Whether native kernels may be used (``TAPLAN_NATIVE`` is not ``0``) and a C compiler is on the path."""
    return os.environ.get("TAPLAN_NATIVE", "1") != "0" and _compiler() is not None


def _compiler() -> str | None:
    return _compiler_on_path(os.environ.get("CC"), os.environ.get("PATH"))


@functools.lru_cache(maxsize=8)
def _compiler_on_path(cc: str | None, path: str | None) -> str | None:
    # cached per (CC, PATH): every new CollisionWorld asks, and a PATH lookup costs ~0.4 ms
    for name in (cc, "cc", "gcc", "clang"):
        if name and shutil.which(name, path=path):
            return name
    return None


def _cache_dir() -> Path:
    root = os.environ.get("TAPLAN_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "taplan"


def _library(function: ca.Function) -> ctypes.CDLL | None:
    """Generate, compile (or find in the cache) and load ``function``'s shared library; None on failure."""
    compiler = _compiler()
    if compiler is None:
        return None
    with tempfile.TemporaryDirectory(prefix="taplan-") as tmp:
        source = Path(tmp) / f"{function.name()}.c"
        generator = ca.CodeGenerator(source.name, {"with_header": False})
        generator.add(function)
        generator.generate(f"{tmp}/")
        code = source.read_bytes()
        digest = hashlib.sha256(code + " ".join((compiler, *_FLAGS)).encode()).hexdigest()[:20]
        if digest in _loaded:
            return _loaded[digest]
        cache = _cache_dir()
        target = cache / f"{function.name()}-{digest}.so"
        if not target.exists():
            built = Path(tmp) / "kernel.so"
            try:
                subprocess.run(
                    [compiler, *_FLAGS, str(source), "-o", str(built), "-lm"],
                    check=True,
                    capture_output=True,
                    timeout=300,
                )
                cache.mkdir(parents=True, exist_ok=True)
                staged = cache / f".{target.name}.{os.getpid()}"
                shutil.copyfile(built, staged)
                os.replace(staged, target)  # atomic: concurrent processes never load a half-written file
            except (OSError, subprocess.SubprocessError) as exc:
                detail = getattr(exc, "stderr", b"") or b""
                warnings.warn(
                    f"taplan: compiling the native kernel {function.name()!r} failed ({exc}; "
                    f"{detail.decode(errors='replace')[:500]}); using the numpy path",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return None
    library = ctypes.CDLL(str(target))
    _loaded[digest] = library
    return library


class NativeFunction:
    """A compiled CasADi function whose inputs and outputs are numpy buffers bound at construction.

    Calling it reads the current contents of the input buffers and overwrites the output buffers; the buffers must
    stay alive and are never reallocated (write into them in place).

    Args:
        function: The CasADi function (dense inputs and outputs).
        library: The loaded library holding its generated code.
        inputs: One float64 C-contiguous buffer per input, with the input's number of elements.
        outputs: One float64 C-contiguous buffer per output, with the output's number of elements.
    """

    def __init__(
        self,
        function: ca.Function,
        library: ctypes.CDLL,
        inputs: Sequence[np.ndarray],
        outputs: Sequence[np.ndarray],
    ) -> None:
        if len(inputs) != function.n_in() or len(outputs) != function.n_out():
            raise ValueError(f"{function.name()}: {function.n_in()} inputs and {function.n_out()} outputs expected")
        for kind, buffers, count in (("input", inputs, function.nnz_in), ("output", outputs, function.nnz_out)):
            for i, buffer in enumerate(buffers):
                ok = buffer.dtype == np.float64 and buffer.flags.c_contiguous and buffer.size == count(i)
                if not ok:
                    raise ValueError(f"{function.name()}: {kind} {i} must be {count(i)} contiguous float64 values")
        self._keep = (list(inputs), list(outputs), library)
        self._arg = (_DOUBLE_P * max(function.sz_arg(), 1))()
        self._res = (_DOUBLE_P * max(function.sz_res(), 1))()
        for i, buffer in enumerate(inputs):
            self._arg[i] = buffer.ctypes.data_as(_DOUBLE_P)
        for i, buffer in enumerate(outputs):
            self._res[i] = buffer.ctypes.data_as(_DOUBLE_P)
        self._iw = (ctypes.c_longlong * max(function.sz_iw(), 1))()
        self._w = np.zeros(max(function.sz_w(), 1))
        self._w_p = self._w.ctypes.data_as(_DOUBLE_P)
        entry = getattr(library, function.name())
        entry.restype = ctypes.c_int
        self._entry = entry
        self.name = function.name()
        # for compiled callers with buffers of their own (a numba loop): the C entry point
        # ``int f(const double** arg, double** res, long long* iw, double* w, int mem)`` and its array sizes
        self.address = int(ctypes.cast(entry, ctypes.c_void_p).value or 0)
        self.sizes = (function.sz_arg(), function.sz_res(), function.sz_iw(), function.sz_w())

    def __call__(self) -> None:
        if self._entry(self._arg, self._res, self._iw, self._w_p, 0):
            raise RuntimeError(f"native kernel {self.name!r} failed")


def compile_function(
    function: ca.Function, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]
) -> NativeFunction | None:
    """``function`` compiled and bound to the buffers, or None when native code is disabled or cannot be built."""
    if not native_enabled():
        return None
    known = _by_function.get(id(function))
    if known is not None and known[0] is function:
        library = known[1]
    else:
        library = _library(function)
        if library is None:
            return None
        _by_function[id(function)] = (function, library)
    return NativeFunction(function, library, inputs, outputs)
