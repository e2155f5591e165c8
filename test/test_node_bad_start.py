"""Every node refuses a bad start-up parameter the same way: one line on stderr, exit code 2, no traceback."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

BIN = Path(sys.executable).parent

CASES = [
    ("hyst_controller_node", ["-p", "rate:=-5.0"], "rate"),
    ("hyst_reference_node", ["-p", "frequency:=-5.0"], "frequency"),
    ("hyst_sim_node", ["-p", "rate:=-5.0"], "rate"),
    ("hyst_driver_node", ["-p", "rate:=-5.0"], "rate"),
    ("hyst_ident_node", ["-p", "poll_period:=-1.0"], "poll_period"),
    ("hyst_ident_node", ["-p", "watch_dir:=/nope/never"], "watch_dir"),
    ("hyst_residual_node", ["-p", "model.y_scale:=1e-6", "-p", "history:=-1.0"], "history"),
    ("hyst_residual_node", [], "--params-file"),  # no model given: it would speak model units
]


@pytest.mark.parametrize("exe,params,name", CASES, ids=[f"{c[0]}-{c[2].strip('-')}" for c in CASES])
def test_bad_start_parameter_is_one_line_and_exit_2(exe, params, name):
    path = shutil.which(exe, path=str(BIN)) or shutil.which(exe)
    assert path, f"{exe} not installed"
    r = subprocess.run([path, "--ros-args", *params], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ))
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and len(lines) == 1, r.stderr[-2000:]
    assert lines[0].startswith(f"{exe}:") and name in lines[0]
