"""`hyst fit` and `hyst simulate` end to end (in process): outputs, params files, and bad-input exits."""
import json

import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.io import read_csv, read_params, write_csv, write_state_bag

TRUE = pea_default().replace(offset=-1.6e-6)


def _data(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 5e-4
    u = 75 + 50 * np.sin(2 * np.pi * 2 * t) + 20 * np.sin(2 * np.pi * 9 * t)
    return t, u, TRUE.simulate(u) + rng.normal(0, 2e-9, n)


def _err(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert not any("Traceback" in line for line in err)
    return err[-1] if err else ""


@pytest.fixture
def bag(tmp_path):
    t, u, y = _data()
    return write_state_bag(tmp_path / "run", t, u, y)


def test_fit_bag_json_and_params_file(tmp_path, bag, capsys):
    out = tmp_path / "p.yaml"
    assert main(["fit", str(bag), "--json", "--quiet", "--out", str(out)]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert {"model", "effects", "method", "rmse", "rmse_train", "seconds", "params"} <= set(obj)
    assert obj["model"] == "mbw" and obj["effects"] == [] and obj["method"] == "fast"
    assert obj["rmse"] < 5e-9 and obj["rmse_train"] < 5e-9  # noise 2 nm
    spec = read_params(out)
    assert spec.fit["method"] == "fast" and abs(spec.fit["rmse"] - obj["rmse"]) < 1e-15
    assert spec.config["dt"] == pytest.approx(5e-4)
    # never overwritten without --force: exit 2, one line, file untouched
    before = out.read_text()
    assert main(["fit", str(bag), "--quiet", "--out", str(out)]) == 2
    assert "exists; use --force" in _err(capsys) and out.read_text() == before
    assert main(["fit", str(bag), "--quiet", "--json", "--out", str(out), "--force", "--model", "bw"]) == 0
    assert read_params(out).base == "bw"


def test_fit_csv_with_columns_units_and_train_window(tmp_path, capsys):
    t, u, y = _data()
    p = tmp_path / "d.csv"
    write_csv(p, {"time_ms": t * 1e3, "volts": u, "disp_um": y * 1e6})
    assert main(["fit", str(p), "--columns", "time_ms,volts,disp_um", "--units", "ms,V,um", "--train", "0.1:1.0",
                 "--json", "--quiet"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["rmse"] < 5e-9 and "0.1 <= t < 1 s" in obj["split"]


def test_simulate_reproduces_the_fitted_record(tmp_path, bag, capsys):
    out = tmp_path / "p.yaml"
    assert main(["fit", str(bag), "--quiet", "--out", str(out)]) == 0
    t, u, y = _data()
    write_csv(tmp_path / "u.csv", {"t": t, "u": u})
    assert main(["simulate", "--params", str(out), "--input", str(tmp_path / "u.csv"),
                 "--out", str(tmp_path / "y.csv")]) == 0
    rec = read_csv(tmp_path / "y.csv")
    assert np.sqrt(np.mean((rec.y - y) ** 2)) < 5e-9  # includes the fitted −1.6 µm offset
    assert abs(rec.y[0] - TRUE.simulate(u[:1])[0]) < 1e-8  # starts from rest, offset applied
    assert main(["simulate", "--params", str(out), "--input", str(tmp_path / "u.csv"),
                 "--out", str(tmp_path / "y.csv")]) == 2
    assert "exists" in _err(capsys)
    write_csv(tmp_path / "u2.csv", {"t": t[::2], "u": u[::2]})  # 1 kHz input for a 2 kHz model
    assert main(["simulate", "--params", str(out), "--input", str(tmp_path / "u2.csv"),
                 "--out", str(tmp_path / "y2.csv")]) == 2
    assert "identified at 2000 Hz" in _err(capsys) and not (tmp_path / "y2.csv").exists()


def _bad_inputs(tmp_path):
    t, u, y = _data(200)
    good = write_state_bag(tmp_path / "good", t, u, y)
    empty = write_state_bag(tmp_path / "empty", [], [], [])
    trunc = write_state_bag(tmp_path / "trunc.mcap", t, u, y)
    trunc.write_bytes(trunc.read_bytes()[:300])
    y_nan = y.copy()
    y_nan[7] = np.nan
    nan = write_state_bag(tmp_path / "nan", t, u, y_nan)
    csv = tmp_path / "d.csv"
    csv.write_text("t_s,voltage_V,displacement_um\n" + "\n".join(f"{a},{b},{c * 1e6}" for a, b, c in zip(t, u, y)))
    return {
        "missing topic": ([str(good), "--topic", "/nope"], "no topic '/nope'"),
        "empty bag": ([str(empty)], "no messages"),
        "truncated bag": ([str(trunc)], "cannot open bag"),
        "nan rows": ([str(nan)], "NaN"),
        "unknown columns": ([str(csv)], "not in the header"),
        "unknown column name": ([str(csv), "--columns", "t_s,volt,displacement_um"], "volt"),
        "wrong units": ([str(csv), "--columns", "t_s,voltage_V,displacement_um", "--units", "s,V,parsec"],
                        "unknown unit 'parsec'"),
        "unknown effect": ([str(good), "--effects", "nosuch"], "nosuch"),
        "unknown model": ([str(good), "--model", "nosuch"], "unknown model"),
        "missing file": ([str(tmp_path / "none.csv")], "no such"),
    }


@pytest.mark.parametrize("case", ["missing topic", "empty bag", "truncated bag", "nan rows", "unknown columns",
                                  "unknown column name", "wrong units", "unknown effect", "unknown model",
                                  "missing file"])
def test_bad_input_one_message_exit_2(tmp_path, capsys, case):
    argv, match = _bad_inputs(tmp_path)[case]
    out = tmp_path / "p.yaml"
    assert main(["fit", *argv, "--quiet", "--out", str(out)]) == 2
    line = _err(capsys)
    assert line.startswith("hyst fit: error:") and match in line
    assert not out.exists()


def test_console_script_exit_code(tmp_path):
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "hyst_model.cli.main", "fit", str(tmp_path / "nothing")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "no such" in r.stderr


@pytest.mark.parametrize("argv, why", [
    (["--resample", "1e9"], "would make"),                 # 45 GiB of samples: a MemoryError traceback
    (["--resample", "0"], "--resample: needs a finite number > 0"),  # silently no resampling
    (["--method", "epso", "--seed", "-1"], "--seed: needs a whole number >= 0"),  # numpy's ValueError
    (["--method", "epso", "--iterations", "0"], "--iterations: needs a whole number >= 1"),
])
def test_bad_numbers_are_one_line_and_exit_2(tmp_path, capsys, argv, why):
    t, u, y = _data(600)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    with pytest.raises(SystemExit) as e:  # argparse's own refusal, or hyst's one line
        raise SystemExit(main(["fit", str(tmp_path / "r.csv"), "--quiet", *argv]))
    assert e.value.code == 2 and why in _err(capsys)


def test_a_report_directory_is_judged_before_the_diagnosis(tmp_path, capsys):
    """A directory of the user's files was refused after the whole diagnosis — and after --out was written."""
    t, u, y = _data(600)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("precious")
    out = tmp_path / "d.yaml"
    assert main(["diagnose", str(tmp_path / "r.csv"), "--quiet", "--report", str(tmp_path / "mine"),
                 "--out", str(out)]) == 2
    assert "not a hyst report" in _err(capsys) and not out.exists()
    (tmp_path / "f.yaml").write_text("x")
    assert main(["diagnose", str(tmp_path / "r.csv"), "--quiet", "--report", str(tmp_path / "f.yaml")]) == 2
    assert "is a file, not a directory" in _err(capsys)


def test_simulate_refuses_an_input_with_a_gap_in_its_time_stamps(tmp_path, capsys):
    """5 lost samples (or 100 s) in an input ran through silently: the per-sample model stepped across them."""
    t, u, y = _data(1200)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", "--out", str(tmp_path / "p.yaml")]) == 0
    keep = np.r_[0:600, 606:1200]
    write_csv(tmp_path / "gap.csv", {"t": t[keep], "u": u[keep]})
    assert main(["simulate", "--params", str(tmp_path / "p.yaml"), "--input", str(tmp_path / "gap.csv"),
                 "--out", str(tmp_path / "y.csv")]) == 2
    assert "have a gap of" in _err(capsys) and not (tmp_path / "y.csv").exists()


@pytest.mark.parametrize("argv, why", [
    (["--train", "0:0.2", "--split", "tail"], "--train T0:T1 sets the split itself"),
    (["--method", "lsq", "--seed", "5"], "--seed applies to --method epso only"),
    (["--val-fraction", "1"], "--val-fraction must be in [0, 1)"),  # block_mask's own words before
    (["--topic", "/nope"], "--topic and --salvage apply to bags"),
])
def test_options_that_would_be_ignored_are_refused(tmp_path, capsys, argv, why):
    t, u, y = _data(600)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", *argv]) == 2
    assert why in _err(capsys)


@pytest.mark.parametrize("argv, why", [
    (["--effects", "delay", "--config", "delay.side=output", "--config", "delay.side=input"], "given twice"),
    (["--effects", "dynamics", "--config", "dynamics.substeps=2.5"], "a whole number"),  # ran and saved as 2
])
def test_an_effect_setting_given_twice_or_not_whole_is_refused(tmp_path, capsys, argv, why):
    t, u, y = _data(600)
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
    assert main(["fit", str(tmp_path / "r.csv"), "--quiet", *argv]) == 2
    assert why in _err(capsys)
