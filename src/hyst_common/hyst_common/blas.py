"""Single-threaded BLAS for hyst's own processes (set before numpy loads its BLAS).

hyst's linear algebra works on tiny matrices (3×3 ``expm`` in the dynamics effect, 8×8 normal equations in the
fitters). Multithreaded BLAS gains nothing there and loses a lot on a loaded machine: measured on the 2-core test
machine, scipy ``expm`` of a 3×3 matrix took 0.15 ms per call single-threaded and 21 ms under load with the
default thread pool; fit and diagnose were 1.3× slower even idle. Threads are fixed when the BLAS library is
loaded, so this must run before the first ``import numpy``: :mod:`hyst_model` calls it first thing, and the
other hyst packages import :mod:`hyst_model` before anything that loads numpy. A value the user set in the
environment is kept (``OPENBLAS_NUM_THREADS=4 hyst diagnose ...`` uses four).
"""
from __future__ import annotations

import os
import sys

__all__ = ["BLAS_THREAD_VARS", "single_thread_blas"]

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
