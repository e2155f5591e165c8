"""The params file records the input range a model was identified on; simulate and compare say when an input
leaves it (the model extrapolates there), and say nothing inside it."""
from __future__ import annotations

import json

import numpy as np
import yaml

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.identify.input_range import identified_range, range_note
from hyst_model.io import write_csv


def test_range_note_only_beyond_the_tolerance():
    fit = identified_range(np.array([10.0, 50.0, 110.0]))
    assert fit == {"u_min": 10.0, "u_max": 110.0}
    assert range_note(fit, np.array([12.0, 113.0])) is None          # 3 % beyond: the same operating range
    note = range_note(fit, np.array([0.0, 60.0, 150.0]))
    assert note is not None and "0 .. 150 V" in note and "10 .. 110 V" in note and "67%" in note
    assert range_note({}, np.array([0.0, 150.0])) is None              # an older file without a range


def test_fit_stores_the_range_and_simulate_and_compare_warn_beyond_it(tmp_path, capsys):
    t = np.arange(4000) * 5e-4
    u = 75 + 30 * np.sin(2 * np.pi * 2 * t)                            # identified on 45 .. 105 V
    y = pea_default().simulate(u) + 2e-9 * np.random.default_rng(0).standard_normal(t.size)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    params = tmp_path / "p.yaml"
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", "--out", str(params)]) == 0
    fit = next(iter(yaml.safe_load(params.read_text()).values()))["ros__parameters"]["fit"]
    assert fit["u_min"] == u.min() and fit["u_max"] == u.max()
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
