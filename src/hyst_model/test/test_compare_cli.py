"""``hyst compare``: figures on records with known errors, the report directory policy, bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.core.params import pea_default
from hyst_model.io.csvio import write_csv
from hyst_model.io.params_file import spec_from_model, write_params
from hyst_model.model import MBWModel

FS = 1000.0


def _model_and_params(tmp_path):
    p = pea_default()
    model = MBWModel(u_scale=p.u_scale, y_scale=p.y_scale, rate=True)
    theta = model.pack({**p.to_dict(), "offset": 0.0})
    path = write_params(tmp_path / "stage.yaml", spec_from_model(model, theta, dt=1 / FS))
    return model, theta, path


def _input() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(int(6 * FS)) / FS
    u = np.where(t < 1.0, 0.0, 75 - 75 * np.cos(2 * np.pi * 1.0 * (t - 1.0)))
    u[t >= 4.0] = 75 - 75 * np.cos(2 * np.pi * 5.0 * (t[t >= 4.0] - 4.0))
    return t, u


def _run(capsys, argv):
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_json_figures_on_a_record_with_a_known_error(tmp_path, capsys):
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    y_model = model.simulate(theta, t, u)
    rng = np.random.default_rng(0)
    noise = 2e-9 * rng.standard_normal(t.size)
    # A missing even-order term: the stage extends more at high voltage than the model says (asymmetry).
    extra = 3e-7 * ((u - 75) / 75) ** 2
    csv = write_csv(tmp_path / "rec.csv", {"t": t, "u": u, "y": y_model + extra + noise})
    code, out, err = _run(capsys, ["compare", str(csv), "--params", str(params), "--json"])
    assert code == 0, err
    d = json.loads(out)
    assert d["model"] == "mbw" and d["n"] == t.size
    assert d["overall"]["rmse"] == pytest.approx(np.sqrt(np.mean((extra + noise) ** 2)), rel=1e-6)
    kinds = [s["kind"] for s in d["segments"]]
    assert kinds[0] == "hold" and [round(s["freq"]) for s in d["segments"] if s["kind"] == "sine"] == [1, 5]
    assert d["higher_order"]["e_u2"]["significant"]
    assert any("even (quadratic)" in f for f in d["findings"])
    # the error is largest at the input extremes: the level table shows it
    lv = [x["rmse"] for x in d["levels"]]
    assert lv[2] < lv[0] and lv[2] < lv[-1]


def test_perfect_model_is_at_the_noise_floor(tmp_path, capsys):
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    rng = np.random.default_rng(1)
    y = model.simulate(theta, t, u) + 5e-9 * rng.standard_normal(t.size)
    csv = write_csv(tmp_path / "rec.csv", {"t": t, "u": u, "y": y})
    code, out, _ = _run(capsys, ["compare", str(csv), "--params", str(params), "--json"])
    d = json.loads(out)
    assert code == 0
    assert d["overall"]["rmse"] == pytest.approx(5e-9, rel=0.05)
    assert not d["whiteness"]["significant"] and not d["cross"]["significant"]
    assert any("sensor noise level" in f for f in d["findings"])


@pytest.mark.slow
def test_text_summary_and_report_dir_policy(tmp_path, capsys):
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    y = model.simulate(theta, t, u)
    # A model whose loop is too narrow: the measurement lags behind on each branch.
    du = np.diff(u, prepend=u[0])
    y = y - 2e-7 * np.sign(du)
    csv = write_csv(tmp_path / "rec.csv", {"t": t, "u": u, "y": y})
    rep = tmp_path / "rep"
    code, out, err = _run(capsys, ["compare", str(csv), "--params", str(params), "--report", str(rep)])
    assert code == 0, err
    assert "by segment:" in out and "by frequency band:" in out and "residual tests" in out
    assert "the measured loop is wider than the model's" in out
    assert (rep / "index.html").is_file() and (rep / "loop.png").stat().st_size > 1000
    # A second report into the same hyst directory replaces it.
    assert _run(capsys, ["compare", str(csv), "--params", str(params), "--report", str(rep)])[0] == 0
    # A directory with somebody else's files is refused and left untouched.
    other = tmp_path / "thesis"
    other.mkdir()
    (other / "chapter1.tex").write_text("precious")
    code, out, err = _run(capsys, ["compare", str(csv), "--params", str(params), "--report", str(other)])
    lines = [ln for ln in err.splitlines() if "warning: subcommand" not in ln]
    assert code == 2 and len(lines) == 1 and "not a hyst report" in lines[0]
    assert sorted(p.name for p in other.iterdir()) == ["chapter1.tex"]
    assert (other / "chapter1.tex").read_text() == "precious"


def test_window_and_csv_columns_units(tmp_path, capsys):
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    y = model.simulate(theta, t, u)
    y_err = y + np.where(t >= 4.0, 1e-7, 0.0)
    csv = write_csv(tmp_path / "lab.csv", {"time_ms": t * 1e3, "volts": u, "disp_um": y_err * 1e6})
    argv = ["compare", str(csv), "--params", str(params), "--json", "--columns", "time_ms,volts,disp_um",
            "--units", "ms,V,um"]
    code, out, err = _run(capsys, argv + ["--window", "0:3.9"])
    assert code == 0, err
    d = json.loads(out)
    assert d["overall"]["rmse"] < 1e-12 and d["n"] == 3900
    # The model runs over the whole record (hysteresis has memory); only the window is scored.
    d = json.loads(_run(capsys, argv + ["--window", "4:"])[1])
    assert d["overall"]["rmse"] == pytest.approx(1e-7, rel=1e-6) and d["n"] == 2000


@pytest.mark.parametrize("argv,msg", [
    (["compare", "{tmp}/missing.csv", "--params", "{params}"], "no such file"),
    (["compare", "{csv}", "--params", "{tmp}/nope.yaml"], "no such params file"),
    (["compare", "{csv}", "--params", "{params}", "--columns", "a,b,c"], "not in the header"),
    (["compare", "{csv}", "--params", "{params}", "--window", "5"], "--window"),
    (["compare", "{csv}", "--params", "{params}", "--window", "10:20"], "no samples"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, msg):
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    csv = write_csv(tmp_path / "rec.csv", {"t": t, "u": u, "y": model.simulate(theta, t, u)})
    argv = [a.format(tmp=tmp_path, params=params, csv=csv) for a in argv]
    code, out, err = _run(capsys, argv)
    lines = [ln for ln in err.splitlines() if "warning: subcommand" not in ln]
    assert code == 2 and len(lines) == 1 and msg in lines[0] and "Traceback" not in err
    assert out == ""


def test_compare_reads_a_state_bag(tmp_path, capsys):
    from hyst_model.io.bag import write_state_bag
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    y = model.simulate(theta, t, u) + 4e-8
    bag = write_state_bag(tmp_path / "run1", t, u, y)
    code, out, err = _run(capsys, ["compare", str(bag), "--params", str(params), "--json"])
    assert code == 0, err
    d = json.loads(out)
    assert d["n"] == t.size and d["overall"]["rmse"] == pytest.approx(4e-8, rel=1e-6)
    assert d["overall"]["bias"] == pytest.approx(4e-8, rel=1e-6)
    assert any("constant offset" in f for f in d["findings"])
    code, _, err = _run(capsys, ["compare", str(bag), "--params", str(params), "--topic", "/nope"])
    assert code == 2 and "Traceback" not in err


def test_a_record_at_another_rate_is_refused_unless_asked_as_simulate_does(tmp_path, capsys):
    """compare only noted what simulate refuses: a per-sample model at twice its rate is another model."""
    model, theta, params = _model_and_params(tmp_path)
    t, u = _input()
    t2 = t[::2] * 1.0  # the same voltages at 500 Hz: every other sample, the time axis kept
    y = model.simulate(theta, t2, u[::2])
    csv = write_csv(tmp_path / "slow.csv", {"t": t2, "u": u[::2], "y": y})
    code, out, err = _run(capsys, ["compare", str(csv), "--params", str(params), "--json"])
    assert code == 2 and "identified at 1000 Hz" in err and "--any-rate" in err and not out
    code, out, err = _run(capsys, ["compare", str(csv), "--params", str(params), "--json", "--any-rate"])
    assert code == 0 and any("do not transfer across sample rates" in n for n in json.loads(out)["notes"])
