"""Single-threaded BLAS for hyst's own processes (set before numpy loads its BLAS).

hyst's linear algebra works on tiny matrices (3×3 ``expm`` in the dynamics effect, 8×8 normal equations in the
fitters). Multithreaded BLAS gains nothing there and loses a lot on a loaded machine: measured on the 2-core test
machine, scipy ``expm`` of a 3×3 matrix took 0.15 ms per call single-threaded and 21 ms under load with the
default thread pool; fit and diagnose were 1.3× slower even idle. Threads are fixed when the BLAS library is
loaded, so this must run before the first ``import numpy``: :mod:`hyst_model` calls it first thing, and the
other hyst packages import :mod:`hyst_model` before anything that loads numpy. A value the user set in the
environment is kept for the rest of the process.

Results must not depend on the thread count either: a threaded BLAS sums the large products of a fit (the
Jacobian's) in another order, and a fit that starts from last-bit differences can end in another basin — generated
GMA stage 6400134's base fit ended at 179 nm with numpy's two default threads and at 94 nm with one, and the
diagnosis named creep instead of saturation. A caller who imported numpy first (a notebook) or set the variables
gets the same answers: :func:`one_blas_thread` runs hyst's fits and diagnoses with one BLAS thread through
threadpoolctl, whatever the library was loaded with.
"""
from __future__ import annotations

import functools
import os
import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["BLAS_THREAD_VARS", "single_thread_blas", "one_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])
_depth = 0  # calls inside an outer one_blas_thread: the limit is already in force
_lock = threading.Lock()

#: Environment variables read by OpenBLAS, OpenMP, MKL, BLIS, Apple Accelerate and numexpr at load time.
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def single_thread_blas() -> bool:
    """Default every BLAS thread-count variable to 1 unless the user set it.

    Returns
    -------
    bool
        True if numpy was not loaded yet (the setting takes effect), False if it came too late.
    """
    for var in BLAS_THREAD_VARS:
        os.environ.setdefault(var, "1")
    return "numpy" not in sys.modules


def one_blas_thread(fn: F) -> F:
    """Decorator: ``fn`` runs with one BLAS thread whatever numpy was loaded with (threadpoolctl; a no-op where it
    is not installed). Nested and concurrent calls inside an outer one keep the outer limit (the thread pool is
    the process's: the diagnosis fits its candidates in threads)."""
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        global _depth
        with _lock:
            outer = _depth > 0
            _depth += 1
        try:
            if outer:
                return fn(*args, **kwargs)
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:  # pragma: no cover - a dependency; without it the environment decides
                return fn(*args, **kwargs)
            with threadpool_limits(limits=1, user_api="blas"):
                return fn(*args, **kwargs)
        finally:
            with _lock:
                _depth -= 1
    return wrapper  # type: ignore[return-value]
