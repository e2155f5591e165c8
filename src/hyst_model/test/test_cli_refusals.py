"""Bad command lines a careless lab user types: each one message and exit 2 before any work, nothing written or
lost (the forty-second session's review of the ``hyst`` command line found each of these accepted)."""
from __future__ import annotations

import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.io import write_csv, write_state_bag


def _csv(path, n=600):
    t = np.arange(n) * 5e-4
    u = 75 + 50 * np.sin(2 * np.pi * 2 * t)
    write_csv(path, {"t": t, "u": u, "y": pea_default().simulate(u)})
    return path


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert not any("Traceback" in line for line in err)
    return err[-1] if err else ""


def test_an_output_that_is_the_input_is_refused_even_with_force(tmp_path, capsys):
    data = _csv(tmp_path / "run.csv")
    before = data.read_bytes()
    assert main(["fit", str(data), "--quiet", "--out", str(data), "--force"]) == 2
    assert "is the file the command reads" in _err(capsys) and data.read_bytes() == before
    params = tmp_path / "p.yaml"
    assert main(["fit", str(data), "--quiet", "--out", str(params)]) == 0
    kept = params.read_bytes()
    inp = tmp_path / "u.csv"
    write_csv(inp, {"t": np.arange(50) * 5e-4, "u": np.full(50, 10.0)})
    # through another spelling of the same path
    other = tmp_path / "." / "p.yaml"
    assert main(["simulate", "--params", str(params), "--input", str(inp), "--out", str(other), "--force"]) == 2
    assert "is the file the command reads" in _err(capsys) and params.read_bytes() == kept


def test_out_inside_or_equal_to_the_report_is_refused_before_the_diagnosis(tmp_path, capsys):
    data = _csv(tmp_path / "run.csv")
    for out, rep in ((tmp_path / "r", tmp_path / "r"), (tmp_path / "r" / "p.yaml", tmp_path / "r")):
        assert main(["diagnose", str(data), "--quiet", "--out", str(out), "--report", str(rep)]) == 2
        assert "inside the --report directory" in _err(capsys)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]


@pytest.mark.parametrize("argv", [["fit", "{d}", "--out", ""], ["diagnose", "{d}", "--report", ""],
                                  ["fit", "{d}", "--effects", ""], ["fit", "{d}", "--effects", ","],
                                  ["diagnose", "{d}", "--effects", "delay,,creep"]])
def test_empty_values_are_refused_not_ignored(tmp_path, capsys, argv):
    data = _csv(tmp_path / "run.csv")
    assert main([a.format(d=data) for a in argv] + ["--quiet"]) == 2
    assert "empty" in _err(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]


def test_ambiguous_csv_columns_are_refused_and_quoted_headers_read(tmp_path, capsys):
    data = _csv(tmp_path / "run.csv")
    body = data.read_text().split("\n", 1)[1]
    (tmp_path / "dup.csv").write_text("t,u,y,y\n" + "\n".join(f"{r},0" for r in body.splitlines()) + "\n")
    assert main(["fit", str(tmp_path / "dup.csv"), "--quiet"]) == 2
    assert "the column y more than once" in _err(capsys)
    assert main(["fit", str(data), "--quiet", "--columns", "t,t,y"]) == 2
    assert "names t for more than one" in _err(capsys)
    (tmp_path / "quoted.csv").write_text('"t","u","y"\n' + body)
    assert main(["fit", str(tmp_path / "quoted.csv"), "--quiet", "--json"]) == 0


def test_more_level_bins_than_a_table_can_show_are_refused(tmp_path, capsys):
    data = _csv(tmp_path / "run.csv")
    assert main(["fit", str(data), "--quiet", "--out", str(tmp_path / "p.yaml")]) == 0
    assert main(["compare", str(data), "--params", str(tmp_path / "p.yaml"), "--levels", "100000"]) == 2
    assert "at most 100" in _err(capsys)


def test_a_params_file_without_dt_says_the_rate_was_not_checked(tmp_path, capsys):
    data = _csv(tmp_path / "run.csv")
    p = tmp_path / "p.yaml"
    assert main(["fit", str(data), "--quiet", "--out", str(p)]) == 0
    lines = p.read_text().splitlines()
    assert sum(1 for ln in lines if ln.strip().startswith("dt:")) == 1
    (tmp_path / "nodt.yaml").write_text("\n".join(ln for ln in lines if not ln.strip().startswith("dt:")) + "\n")
    capsys.readouterr()
    assert main(["simulate", "--params", str(tmp_path / "nodt.yaml"), "--input", str(data),
                 "--out", str(tmp_path / "o.csv")]) == 0
    assert "gives no model.dt" in capsys.readouterr().err
    assert main(["compare", str(data), "--params", str(tmp_path / "nodt.yaml")]) == 0
    assert "gives no model.dt" in capsys.readouterr().err
    assert main(["compare", str(data), "--params", str(p)]) == 0
    assert "gives no model.dt" not in capsys.readouterr().err


def test_a_folder_of_bags_is_named_as_such(tmp_path, capsys):
    t = np.arange(300) * 5e-4
    u = 75 + 50 * np.sin(2 * np.pi * 2 * t)
    write_state_bag(tmp_path / "bags" / "run1", t, u, pea_default().simulate(u))
    assert main(["fit", str(tmp_path / "bags"), "--quiet"]) == 2
    assert "is a folder of bags (run1)" in _err(capsys)
    (tmp_path / "empty").mkdir()
    assert main(["fit", str(tmp_path / "empty"), "--quiet"]) == 2
    assert "not a bag" in _err(capsys)
