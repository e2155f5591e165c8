"""hyst's processes default to one BLAS thread, set before numpy loads, and keep a user's own setting."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = ("import {pkg}, os, sys; "
         "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'], 'numpy' in sys.modules)")


@pytest.mark.parametrize("pkg", ["hyst_model", "hyst_control", "hyst_sim", "hyst_driver", "hyst_model.cli.main"])
def test_every_package_sets_one_blas_thread_before_numpy(pkg):
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", PROBE.format(pkg=pkg)], env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    assert out[:2] == ["1", "1"], out


def test_a_users_thread_setting_is_kept():
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env["OPENBLAS_NUM_THREADS"] = "3"
    out = subprocess.run([sys.executable, "-c", PROBE.format(pkg="hyst_model")], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out[:2] == ["3", "1"]


def test_it_reports_when_it_comes_too_late():
    import numpy  # noqa: F401  (loaded by the test session already)

    from hyst_common.blas import single_thread_blas
    assert single_thread_blas() is False


FITS_ON_ONE = """
import os, sys
import numpy as np                      # first, as a notebook does: the BLAS pool has the environment's threads
from threadpoolctl import threadpool_info
from hyst_common.blas import one_blas_thread
import hyst_model.identify as identify
import hyst_model.diagnose.diagnose as dg
import hyst_model.identify.admissible as adm

def blas_threads():
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

inside = one_blas_thread(blas_threads)
print(set(blas_threads()), set(inside()), set(blas_threads()),
      all(hasattr(f, "__wrapped__") for f in (identify.fit, dg.diagnose, adm.constrain)))
"""


def test_fits_and_diagnoses_run_on_one_blas_thread_whatever_numpy_was_loaded_with():
    """A threaded BLAS sums a fit's products in another order and the fit can end elsewhere: generated GMA stage
    6400134 was diagnosed creep with numpy's two default threads and saturation with one."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env["OPENBLAS_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", FITS_ON_ONE], env=env, capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "{2} {1} {2} True", out  # numpy's and scipy's OpenBLAS each
