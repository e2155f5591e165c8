"""The excitation ``hyst diagnose`` advises stays where the record's stage was driven (diagnose.undetermined).

A record of another stage (±10 V, 0–200 V) is neither amplifier profile: the advice must not fall back to a
profile's default range (the PEA's 0–150 V would drive a ±10 V stage fifteen times beyond its record).
"""
from __future__ import annotations

import shlex

import pytest

from hyst_model.cli.main import main as hyst
from hyst_model.diagnose.undetermined import excite_command
from hyst_model.io.csvio import read_input_csv


@pytest.mark.parametrize("u_range,profile", [
    ((0.0, 120.0), "pea"), ((-4.0, 4.5), "gma"), ((-10.0, 10.0), "custom"), ((0.0, 200.0), "custom"),
    ((-3.0, 9.0), "custom"), ((20.0, 140.0), "pea"), ((0.5, 150.0), "pea"), ((-120.0, -20.0), "custom"),
])
def test_the_advised_excitation_runs_and_stays_inside_the_records_range(tmp_path, capsys, u_range, profile):
    cmd = excite_command(1e-3, u_range)
    assert f"--profile {profile}" in cmd and "--rate 1000" in cmd
    argv = shlex.split(cmd)[1:]
    out = tmp_path / "excite.csv"
    argv[argv.index("--out") + 1] = str(out)
    assert hyst(argv) == 0, capsys.readouterr().err
    t, u = read_input_csv(out)
    lo, hi = u_range
    # the record's reach for a bipolar profile, its own range for the PEA and another stage
    assert u.max() <= hi and u.min() >= ((lo if lo > 1.5 else 0.0) if profile == "pea" else -max(abs(lo), hi))
    if profile == "custom":
        assert lo <= u.min() and u.max() <= hi
        assert u.max() - u.min() > 0.5 * (hi - lo)          # it does use the range


def test_without_a_range_the_command_is_the_generic_one():
    assert excite_command(None, None) == "hyst excite --parts steps,noise,sweep --out excite.csv"
    assert excite_command(float("nan"), (float("nan"), 1.0)) == "hyst excite --parts steps,noise,sweep --out excite.csv"
