"""One BLAS thread around the sparse eigen-solve.

ARPACK's Lanczos iteration (scipy's ``eigsh``) and SuperLU's triangular
solves call BLAS hundreds of times on thin operands (level-2 operations on
``n x ncv`` blocks).  A threaded OpenBLAS hands each call to its threads and
waits for them; on a machine whose cores are busy with other work the waiting
costs more than the arithmetic: profiled on a loaded 2-core machine, most of
the eigen-solve's time went to ARPACK's own calls, waiting.
``benchmarks/plane_setup.py`` times the modes both ways side by side
(docs/performance.md).

:func:`one_blas_thread` sets the OpenBLAS libraries loaded in the process
(numpy's and scipy's bundled copies, found by their exported
``*openblas_set_num_threads*`` functions) to one thread for the duration of a
``with`` block and gives each back its count after.  Where none is found (not
Linux, another BLAS), it does nothing.  Set ``COSIM_BLAS_THREADS=keep`` to
leave the threads alone.  The count is process-wide, and changing it while
another thread is inside OpenBLAS is not safe: where the process runs other
Python threads (a threaded sweep, a Dask scheduler), it is left alone.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading

__all__ = ["one_blas_thread", "openblas_controls"]

#: (getter, setter) names an OpenBLAS build exports, plain and as numpy's and
#: scipy's wheels rename them
_NAMES = tuple((f"{p}openblas_get_num_threads{s}", f"{p}openblas_set_num_threads{s}")
               for p in ("", "scipy_") for s in ("", "64_"))

_FOUND: tuple | None = None


def _loaded_libraries() -> list[str]:
    """Paths of the shared libraries of this process whose name holds
    ``openblas`` (Linux: ``/proc/self/maps``)."""
    if not sys.platform.startswith("linux"):
        return []
    paths = set()
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                parts = line.split(None, 5)
                if len(parts) == 6:
                    path = parts[5].strip()
                    name = os.path.basename(path).lower()
                    if "openblas" in name and ".so" in name:
                        paths.add(path)
    except OSError:
        return []
    return sorted(paths)


def openblas_controls() -> list:
    """``(get, set)`` of the thread count of each OpenBLAS loaded now
    (numpy's, and scipy's once scipy's linear algebra is imported: the
    libraries are looked up again whenever their set has changed)."""
    global _FOUND
    paths = tuple(_loaded_libraries())
    if _FOUND is not None and _FOUND[0] == paths:
        return _FOUND[1]
    found = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)           # already loaded: its handle
        except OSError:
            continue
        for get_name, set_name in _NAMES:
            get, put = getattr(lib, get_name, None), getattr(lib, set_name, None)
            if get is not None and put is not None:
                get.restype, get.argtypes = ctypes.c_int, []
                put.restype, put.argtypes = None, [ctypes.c_int]
                found.append((get, put))
                break
    _FOUND = (paths, found)
    return found


@contextlib.contextmanager
def one_blas_thread():
    """Run the ``with`` block on one OpenBLAS thread (see the module's notes)."""
    if (os.environ.get("COSIM_BLAS_THREADS", "").strip().lower() == "keep"
            or threading.active_count() > 1):
        # another thread may be inside OpenBLAS: changing its thread count
        # under a call in flight is not safe, so leave it as it is
        yield
        return
    controls = openblas_controls()
    before = [get() for get, _ in controls]
    for (_, put), n in zip(controls, before):
        if n != 1:
            put(1)
    try:
        yield
    finally:
        for (get, put), n in zip(controls, before):
            if get() != n:
                put(n)
