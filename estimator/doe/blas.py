"""Keep OpenBLAS single-threaded inside a running process.

The identifier's matrices are small (8 x 8, a few thousand samples by a few channels);
OpenBLAS's helper threads cannot speed them up but, on a machine whose cores are busy,
their spinning costs 2-10x (measured in ``docs/performance.md``). Setting
``OPENBLAS_NUM_THREADS=1`` only works before numpy is imported; :func:`single_thread_blas`
does the same at run time through OpenBLAS's own ``*_set_num_threads`` entry point
(what *threadpoolctl* does), for every OpenBLAS library mapped into the process.
"""
from __future__ import annotations

import ctypes
import sys

import numpy  # noqa: F401  (makes sure numpy's BLAS is loaded before the search)

_SYMBOLS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads_64_",
            "openblas_set_num_threads64_", "openblas_set_num_threads_64_",
            "openblas_set_num_threads")


def _loaded_openblas() -> list[str]:
    if not sys.platform.startswith("linux"):
        return []
    paths: list[str] = []
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            for line in fh:
                path = line.split()[-1] if line.strip() else ""
                name = path.rsplit("/", 1)[-1].lower()
                if "openblas" in name and ".so" in name and path not in paths:
                    paths.append(path)
    except OSError:
        return []
    return paths


def single_thread_blas(threads: int = 1) -> int:
    """Limit every loaded OpenBLAS to ``threads`` threads; returns how many were set.

    Harmless (returns 0) where OpenBLAS is not used or the platform has no ``/proc``.
    """
    done = 0
    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for sym in _SYMBOLS:
            fn = getattr(lib, sym, None)
            if fn is not None:
                fn.argtypes = [ctypes.c_int]
                fn(int(threads))
                done += 1
                break
    return done
