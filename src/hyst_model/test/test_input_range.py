"""The params file records the input range a model was identified on; simulate and compare say when an input
leaves it (the model extrapolates there), and say nothing inside it."""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.identify.input_range import identified_range, output_note, range_note
from hyst_model.io import write_csv


def test_range_note_only_beyond_the_tolerance():
    fit = identified_range(np.array([10.0, 50.0, 110.0]))
    assert fit == {"u_min": 10.0, "u_max": 110.0}
    assert range_note(fit, np.array([12.0, 113.0])) is None          # 3 % beyond: the same operating range
    note = range_note(fit, np.array([0.0, 60.0, 150.0]))
    assert note is not None and "0 .. 150 V" in note and "10 .. 110 V" in note and "67%" in note
    assert range_note({}, np.array([0.0, 150.0])) is None              # an older file without a range


def test_output_note_only_far_beyond_the_measured_output():
    fit = identified_range(np.array([0.0, 100.0]), np.array([2e-6, 5e-6, 12e-6]))
    assert fit == {"u_min": 0.0, "u_max": 100.0, "y_min": 2e-6, "y_max": 12e-6}
    assert output_note(fit, np.array([-7e-6, 21e-6])) is None          # within one span either side: a wider drive
    note = output_note(fit, np.array([3e-6, 1.46, 4e-6, 5e-6]))        # a diverging fit's 1.46 m
    assert note is not None and "1.46e+06 µm" in note and "2 .. 12 µm" in note and "25%" in note
    assert output_note(fit, np.array([-9e-6, 3e-6])) is not None       # below, too
    assert output_note({"u_min": 0.0, "u_max": 1.0}, np.array([1.0])) is None  # an older file without it


def test_fit_stores_the_range_and_simulate_and_compare_warn_beyond_it(tmp_path, capsys):
    t = np.arange(4000) * 5e-4
    u = 75 + 30 * np.sin(2 * np.pi * 2 * t)                            # identified on 45 .. 105 V
    y = pea_default().simulate(u) + 2e-9 * np.random.default_rng(0).standard_normal(t.size)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    params = tmp_path / "p.yaml"
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", "--out", str(params)]) == 0
    fit = next(iter(yaml.safe_load(params.read_text()).values()))["ros__parameters"]["fit"]
    assert fit["u_min"] == u.min() and fit["u_max"] == u.max()
    assert (fit["y_min"], fit["y_max"]) == pytest.approx((y.min(), y.max()), rel=1e-8)  # as the CSV holds y
    capsys.readouterr()
    wide = 75 + 70 * np.sin(2 * np.pi * 2 * t)                         # 5 .. 145 V
    for name, uu in (("inside", u), ("wide", wide)):
        write_csv(tmp_path / f"{name}.csv", {"t": t, "u": uu})
        assert main(["simulate", "--params", str(params), "--input", str(tmp_path / f"{name}.csv"),
                     "--out", str(tmp_path / f"{name}_y.csv")]) == 0
        err = capsys.readouterr().err
        assert ("outside the" in err) == (name == "wide"), err
    write_csv(tmp_path / "w.csv", {"t": t, "u": wide, "y": pea_default().simulate(wide)})
    assert main(["compare", str(tmp_path / "w.csv"), "--params", str(params), "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any("extrapolates" in n for n in notes)
    assert main(["compare", str(tmp_path / "r.csv"), "--params", str(params), "--json"]) == 0
    assert not any("extrapolates" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_simulate_and_compare_warn_when_the_output_leaves_the_measured_range(tmp_path, capsys):
    t = np.arange(4000) * 5e-4
    u = 75 + 30 * np.sin(2 * np.pi * 2 * t)
    y = pea_default().simulate(u) + 2e-9 * np.random.default_rng(1).standard_normal(t.size)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    params = tmp_path / "p.yaml"
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", "--out", str(params)]) == 0
    write_csv(tmp_path / "in.csv", {"t": t, "u": u})
    out = tmp_path / "y.csv"
    capsys.readouterr()
    assert main(["simulate", "--params", str(params), "--input", str(tmp_path / "in.csv"), "--out", str(out)]) == 0
    assert "far beyond" not in capsys.readouterr().err                 # the record's own input: no note
    doc = yaml.safe_load(params.read_text())
    fit = next(iter(doc.values()))["ros__parameters"]["fit"]
    fit["y_max"] = fit["y_min"] + 0.1 * (fit["y_max"] - fit["y_min"])  # as if it had measured a tenth of the travel
    params.write_text(yaml.safe_dump(doc))
    assert main(["simulate", "--params", str(params), "--input", str(tmp_path / "in.csv"), "--out", str(out),
                 "--force"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "far beyond" in err, err
    assert main(["compare", str(tmp_path / "r.csv"), "--params", str(params), "--json"]) == 0
    assert any("far beyond" in n for n in json.loads(capsys.readouterr().out)["notes"])
