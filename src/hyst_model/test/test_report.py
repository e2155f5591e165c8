"""HTML/PNG report of compare and diagnose: content, error ladder, directory policy."""
from __future__ import annotations

import re

import numpy as np
import pytest

from hyst_model.diagnose.report import MARKER, check_report_dir, write_report
from hyst_model.diagnose.stats import compare_stats
from hyst_model.errors import HystError
from hyst_model.io.record import Record


def _record():
    fs = 500.0
    t = np.arange(int(4 * fs)) / fs
    u = 75 - 75 * np.cos(2 * np.pi * 1.0 * t)
    y = 2e-7 * u + 1e-6 * np.sin(2 * np.pi * t)  # a loop
    yhat = 2e-7 * u
    return Record(t, u, y, {"source": "synthetic <loop>"}), yhat


def _png_ok(p):
    b = p.read_bytes()
    return b[:8] == b"\x89PNG\r\n\x1a\n" and len(b) > 2000


@pytest.mark.slow
def test_report_contains_plots_tables_and_escaped_text(tmp_path):
    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    ladder = [{"model": "mbw", "rmse": 3e-7, "rmse_train": 2.9e-7}, {"model": "mbw+creep", "rmse": 5e-8}]
    diagnosis = {"baseline": {"model": "mbw", "rmse": 3e-7}, "missing": "creep",
                 "candidates": [{"effect": "creep", "rmse": 5e-8, "improvement": 6.0,
                                 "evidence": "residual keeps growing for seconds <log time>"}]}
    d = write_report(tmp_path / "r", rec, yhat, st, ladder=ladder, diagnosis=diagnosis, title="T & T")
    html = (d / "index.html").read_text()
    for name in ("time.png", "loop.png", "residual.png", "spectrum.png", "correlation.png", "ladder.png"):
        assert _png_ok(d / name) and f"src='{name}'" in html
    assert "T &amp; T" in html and "synthetic &lt;loop&gt;" in html and "&lt;log time&gt;" in html
    assert "<b>creep</b>" in html
    # overall RMSE in nm appears in the fit table
    rmse_nm = st.overall.rmse * 1e9
    assert f"{rmse_nm:.4g}" in html
    # one row per segment, per ladder rung
    assert html.count("<td>mbw+creep</td>") == 1
    assert len(re.findall(r"<td>sine 1 Hz</td>", html)) == 1
    assert (d / MARKER).exists()
    assert "Taken out of the record" not in html                       # no line was


@pytest.mark.slow
def test_report_says_which_lines_its_rmses_are_without(tmp_path):
    """The ladder's RMSEs are of the record without the lines diagnose took out, the plots of the record as
    measured: the report says so, naming the lines taken out (not one found only in the final residual)."""
    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    diagnosis = {"baseline": {"model": "mbw", "rmse": 3e-7}, "missing": "none", "candidates": [],
                 "disturbances": [
                     {"frequency": 59.96, "amplitude": 8.03e-9, "ratio": 900.0, "phase": 0.1, "rms": 5.7e-9,
                      "removed": True},
                     {"frequency": 179.9, "amplitude": 2e-9, "ratio": 90.0, "phase": 0.0, "rms": 1.4e-9,
                      "removed": False}]}
    html = (write_report(tmp_path / "r", rec, yhat, st, diagnosis=diagnosis) / "index.html").read_text()
    assert "Taken out of the record before fitting: a line at 59.96 Hz (8.03 nm amplitude)" in html
    assert "179.9" not in html and "record as measured" in html


@pytest.mark.slow
def test_no_ladder_no_ladder_png(tmp_path):
    rec, yhat = _record()
    d = write_report(tmp_path / "r", rec, yhat, compare_stats(rec.t, rec.u, rec.y, yhat))
    assert not (d / "ladder.png").exists() and "Error ladder" not in (d / "index.html").read_text()


def test_directory_policy(tmp_path):
    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    foreign = tmp_path / "data"
    foreign.mkdir()
    (foreign / "run1.csv").write_text("t,u,y\n")
    with pytest.raises(HystError, match="not a hyst report"):
        write_report(foreign, rec, yhat, st)
    assert [p.name for p in foreign.iterdir()] == ["run1.csv"]
    # --force writes next to the user's file and keeps it
    write_report(foreign, rec, yhat, st, force=True)
    assert (foreign / "run1.csv").read_text() == "t,u,y\n" and (foreign / "index.html").exists()
    # a hyst report directory that later got a foreign file is refused too
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(HystError, match="did not write"):
        check_report_dir(foreign)
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(HystError, match="is a file"):
        check_report_dir(f)


def test_length_mismatch_is_an_error(tmp_path):
    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    with pytest.raises(HystError, match="same length"):
        write_report(tmp_path / "r", rec, yhat[:-1], st)
    assert not (tmp_path / "r").exists()


def test_another_commands_report_needs_force_and_a_rerun_leaves_no_stale_plot(tmp_path):
    """hyst compare then hyst diagnose into one directory: the diagnose report replaced the compare report
    without a word (and one written after a diagnose kept its ladder plot)."""
    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    d = tmp_path / "out"
    ladder = [{"model": "mbw", "rmse": 3e-7, "rmse_train": 2.9e-7}, {"model": "mbw+creep", "rmse": 5e-8}]
    write_report(d, rec, yhat, st, ladder=ladder, kind="diagnose")
    assert (d / "ladder.png").exists()
    with pytest.raises(HystError, match="holds a hyst diagnose report"):
        check_report_dir(d, kind="compare")
    with pytest.raises(HystError, match="holds a hyst diagnose report"):
        write_report(d, rec, yhat, st, kind="compare")
    check_report_dir(d, kind="diagnose")  # the same command's re-run is fine
    write_report(d, rec, yhat, st, kind="compare", force=True)
    assert not (d / "ladder.png").exists() and "hyst compare" in (d / MARKER).read_text()


def test_an_interrupted_report_leaves_nothing_and_keeps_the_previous_one(tmp_path, monkeypatch):
    """Ctrl-C while plotting left a directory of PNGs without index.html (and, in diagnose, a params file)."""
    import os
    import stat

    import hyst_model.diagnose.report as report
    from hyst_model.io.modes import user_umask

    rec, yhat = _record()
    st = compare_stats(rec.t, rec.u, rec.y, yhat)
    real = report._plots

    def interrupted(d, *a):
        real(d, *a)  # every plot is on disk, index.html not yet
        raise KeyboardInterrupt
    monkeypatch.setattr(report, "_plots", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_report(tmp_path / "new", rec, yhat, st)
    assert list(tmp_path.iterdir()) == []  # neither the report nor its staging directory
    monkeypatch.setattr(report, "_plots", real)
    d = write_report(tmp_path / "old", rec, yhat, st, ladder=[{"model": "mbw", "rmse": 3e-7}])
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    assert "ladder.png" in before
    assert stat.S_IMODE(d.stat().st_mode) == 0o777 & ~user_umask()  # as mkdir makes it, not mkdtemp's 0700
    monkeypatch.setattr(report, "_plots", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_report(d, rec, yhat, st)
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    assert sorted(os.listdir(tmp_path)) == ["old"]
    monkeypatch.setattr(report, "_plots", real)
    write_report(d, rec, yhat, st)  # a re-run without a ladder: the old ladder plot goes, the rest is replaced
    assert not (d / "ladder.png").exists() and (d / "index.html").read_bytes() != before["index.html"]
    assert sorted(os.listdir(tmp_path)) == ["old"]
