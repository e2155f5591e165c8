"""Plausibility warnings (issue #13): unit mistakes are named before a 'successful' nonsense fit."""
import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.io.plausible import plausibility


def _record(n=4000, fs=1000.0):
    t = np.arange(n) / fs
    u = 75 - 70 * np.cos(2 * np.pi * 1.0 * t)
    y = 2e-7 * u
    return t, u, y


def test_a_plausible_record_gives_no_warning():
    assert plausibility(*_record()) == []
    t, u, y = _record()
    assert plausibility(t, (u - 75) / 15, 1e-6 * (u - 75) / 15) == []  # GMA-like ±5 V, ±5 µm


@pytest.mark.parametrize("what, change, words", [
    ("y in µm read as m", lambda t, u, y: (t, u, y * 1e6), "µm or nm read as metres"),
    ("t in ms read as s", lambda t, u, y: (t * 1000, u, y), "ms or µs read as seconds"),
    ("t in µs read as s", lambda t, u, y: (t * 1e6, u, y), "outside 10 Hz"),
    ("fs above 100 kHz", lambda t, u, y: (t / 1000, u, y), "outside 10 Hz"),
    ("u in mV read as V", lambda t, u, y: (t, u * 1000, y), "mV read as volts"),
])
def test_each_unit_mistake_is_named(what, change, words):
    w = plausibility(*change(*_record()))
    assert len(w) == 1 and words in w[0], (what, w)


def test_another_stages_range_is_no_unit_mistake_but_millivolts_of_it_are():
    t, u, y = _record()
    for v in ((u - 75) / 7.5, u * 4 / 3, (u - 75) * 4):   # ±10 V, 0–200 V, ±300 V stages: beyond the rig's two
        assert plausibility(t, v, y) == [], v.max()
    w = plausibility(t, (u - 75) / 7.5 * 1000, y)          # the ±10 V stage's input in mV read as V
    assert len(w) == 1 and "mV read as volts" in w[0]


def test_input_range_only_checked_for_volts():
    t, u, y = _record()
    assert plausibility(t, u * 1000, y, input_unit="N") == []


def test_cli_prints_the_warning_once_and_still_fits(tmp_path, capsys):
    t, u, y = _record()
    p = tmp_path / "d.csv"
    np.savetxt(p, np.c_[t, u, y * 1e6], delimiter=",", header="t,u,y", comments="")  # µm in a metres column
    assert main(["fit", str(p), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("hyst: warning:") == 1 and "--units s,V,um" in err
    p2 = tmp_path / "ok.csv"
    np.savetxt(p2, np.c_[t, u, y], delimiter=",", header="t,u,y", comments="")
    assert main(["compare", str(p2), "--params", str(_params(tmp_path, p2)), "--json"]) == 0
    assert "hyst: warning:" not in capsys.readouterr().err


def _params(tmp_path, csv):
    out = tmp_path / "p.yaml"
    assert main(["fit", str(csv), "--quiet", "--out", str(out)]) == 0
    return out


def test_a_large_displacement_in_units_the_user_gave_is_not_called_a_unit_mistake(tmp_path, capsys):
    """The Bouc-Wen benchmark's millimetres, given as ``--units s,N,m``: no advice to give the unit again."""
    t, u, y = _record()
    w = plausibility(t, u, y * 1e4, units_given=True)           # 2.8 mm of travel, stated in metres
    assert len(w) == 1 and "in the units given" in w[0] and "--units" not in w[0], w
    p = tmp_path / "big.csv"
    np.savetxt(p, np.c_[t, u, y * 1e4], delimiter=",", header="t,u,y", comments="")
    assert main(["fit", str(p), "--units", "s,N,m", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "in the units given" in err and "--units s,V,um" not in err
