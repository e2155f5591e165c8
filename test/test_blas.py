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
