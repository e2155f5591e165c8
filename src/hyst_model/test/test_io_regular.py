"""Rig records are fit as they come: repeated lockstep stamps collapsed, missed periods bridged or cut, reported."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.errors import DataError
from hyst_model.io import load_record, regularise, write_state_bag
from hyst_model.io.record import Record

DT = 1e-3


def _stage(n: int = 4000, seed: int = 0):
    """A seeded record from the one MBW recursion (the embedded PEA stage) with 2 nm noise."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(n)
    u = 75.0 + 60.0 * np.sin(2 * np.pi * 2.0 * t) + 10.0 * np.sin(2 * np.pi * 7.0 * t)
    return t, u, pea_default().simulate(u) + 2e-9 * rng.standard_normal(n)


def _lockstep_copies(t, u, y, copies: int = 4):
    """Sample 0 published ``copies`` times with the same stamp, as the lockstep sim does until answered."""
    idx = np.r_[np.zeros(copies - 1, dtype=int), np.arange(t.size)]
    return t[idx], u[idx], y[idx]


def test_repeated_stamps_collapse_to_one_sample():
    t, u, y = _stage(200)
    rec, notes = regularise(Record(*_lockstep_copies(t, u, y)))
    np.testing.assert_array_equal(rec.t, t)
    np.testing.assert_array_equal(rec.y, y)
    assert notes == ["collapsed 3 repeated time stamp(s) (identical copies)"]
    with pytest.raises(DataError, match="not strictly increasing.*--gaps auto"):
        regularise(Record(*_lockstep_copies(t, u, y)), "refuse")


def test_short_gaps_are_bridged_with_the_input_held():
    t, u, y = _stage(300)
    keep = np.r_[0:100, 103:200, 207:300]          # 3 and 7 periods missed
    rec, notes = regularise(Record(t[keep], u[keep], y[keep]), "bridge")
    assert len(rec) == 300 and np.allclose(np.diff(rec.t), DT)
    assert rec.meta["bridged"] == [100, 101, 102, 200, 201, 202, 203, 204, 205, 206]
    np.testing.assert_array_equal(rec.u[100:103], u[99])        # held, as the DAC holds it
    np.testing.assert_allclose(rec.y[100:103], np.interp(t[100:103], t[[99, 103]], y[[99, 103]]))
    assert "bridged 2 gap(s)" in notes[0] and "10 samples, longest 7" in notes[0]
    rec.check()


def test_long_gaps_cut_to_the_longest_segment_or_refuse():
    t, u, y = _stage(1000)
    keep = np.r_[0:300, 302:500, 600:1000]        # a 2-period gap (bridged) and a 100-period gap (cut)
    r = Record(t[keep], u[keep], y[keep])
    rec, notes = regularise(r, "auto")
    assert len(rec) == 500 and rec.meta["bridged"] == [300, 301]       # 0..499 with the bridge, then cut
    assert any("longer than 10 periods" in n for n in notes)
    with pytest.raises(DataError, match="cannot be bridged; use --gaps longest"):
        regularise(r, "bridge")
    rec, _ = regularise(r, "longest")
    assert len(rec) == 400


def test_time_running_backwards_stays_an_error():
    t, u, y = _stage(100)
    t = t.copy()
    t[50] = t[40]
    with pytest.raises(DataError, match="time runs backwards"):
        regularise(Record(t, u, y))


def test_bridging_is_exact_when_the_stage_held_the_input():
    """Missed periods of a stage whose DAC held the voltage: the bridged record fits to the noise floor."""
    t, u, _ = _stage(3000)
    rng = np.random.default_rng(5)
    missed = np.sort(rng.choice(np.arange(100, 2900), 40, replace=False))
    u_held = u.copy()
    for k in missed:                                   # in order, so runs of missed samples hold one value
        u_held[k] = u_held[k - 1]
    y = pea_default().simulate(u_held)
    keep = np.setdiff1d(np.arange(3000), missed)
    rec, _ = regularise(Record(t[keep], u_held[keep], y[keep]))
    np.testing.assert_array_equal(rec.u, u_held)
    np.testing.assert_allclose(pea_default().simulate(rec.u), y, rtol=0, atol=1e-15)


def test_hyst_fit_reads_a_lockstep_bag_with_missed_periods_as_it_is(tmp_path, capsys):
    t, u, y = _stage(4000)
    keep = np.r_[0:1500, 1502:4000]
    tt, uu, yy = _lockstep_copies(t[keep], u[keep], y[keep])
    bag = write_state_bag(tmp_path / "run", tt, uu, yy)
    with pytest.raises(DataError):
        load_record(bag).check()
    assert main(["fit", str(bag), "--json", "--quiet"]) == 0
    out, err = capsys.readouterr()
    obj = json.loads(out)
    assert obj["samples"] == 4000 and any("collapsed 3" in n for n in obj["data_notes"])
    assert "bridged 1 gap(s)" in err
    assert obj["rmse"] < 20e-9                      # the noise is 2 nm: the bridge did not spoil the fit
    assert main(["fit", str(bag), "--gaps", "refuse", "--quiet"]) == 2
    assert "--gaps auto" in capsys.readouterr().err
    # diagnose and compare keep the notes too (they only printed them): JSON and params file alike
    assert main(["fit", str(bag), "--quiet", "--out", str(tmp_path / "fit.yaml")]) == 0
    capsys.readouterr()
    assert main(["compare", str(bag), "--params", str(tmp_path / "fit.yaml"), "--json"]) == 0
    assert any("bridged 1 gap(s)" in n for n in json.loads(capsys.readouterr().out)["data_notes"])
    assert main(["diagnose", str(bag), "--json", "--effects", "delay", "--out", str(tmp_path / "d.yaml")]) in (0, 3)
    assert any("collapsed 3" in n for n in json.loads(capsys.readouterr().out)["data_notes"])
    from hyst_model.io import read_params
    prov = read_params(tmp_path / "d.yaml").fit
    assert "collapsed 3" in prov["data_notes"] and prov["samples"] == 4000 and "interleaved" in prov["split"]


def test_auto_keeps_the_segment_with_the_excitation_not_the_longer_rest_after_it():
    """A realtime run: excitation, a long stall, then the stage resting at v_safe for longer than it was excited
    (the recorder ran on). The longest segment holds nothing to identify; auto keeps the excited one."""
    t, u, y = _stage(3000)
    u = u.copy()
    u[1200:] = 0.0                                 # rest after the excitation
    keep = np.r_[0:1000, 1100:3000]                # a 100-period stall: cut
    rec, notes = regularise(Record(t[keep], u[keep], y[keep]), "auto")
    assert len(rec) == 1000 and rec.t[0] == 0.0
    assert any("varies most" in n for n in notes), notes
    rec, _ = regularise(Record(t[keep], u[keep], y[keep]), "longest")   # as asked: the longest
    assert len(rec) == 1900


def test_a_step_just_over_the_limit_of_the_kept_segment_is_bridged_too():
    """Jittered real-time stamps: a 1.5 ms step is regular by the whole record's median period (1.001 ms) and a gap
    by the kept segment's (0.999 ms), which Record.check then uses; CI once saw `hyst fit` refuse such a bag after
    --gaps auto had cut it. The step is bridged by the kept segment's own median, and the result checks."""
    a = 1.001e-3 * np.arange(6000)                       # a hold: the input does not vary
    b0 = a[-1] + 0.05                                    # a 50 ms gap: the record is cut there
    steps = np.full(4999, 0.999e-3)
    steps[2500] = 1.5e-3
    b = b0 + np.r_[0.0, np.cumsum(steps)]
    t = np.r_[a, b]
    u = np.r_[np.full(a.size, 75.0), 75.0 + 60.0 * np.sin(2 * np.pi * 2.0 * (b - b0))]
    y = 1e-7 * u
    out, notes = regularise(Record(t, u, y, {"source": "jittered"}), "auto")
    out.check()
    assert out.t[0] == b[0] and len(out) == b.size + 1, notes     # the sine segment kept, one sample put back
    assert len(out.meta["bridged"]) == 1 and out.u[out.meta["bridged"][0]] == u[a.size + 2500], notes


def test_two_runs_stamped_alike_are_refused_not_spliced():
    """A recorder kept across a restart of the lockstep stage holds two runs stamped from 0: sorted by stamp they
    were spliced into one record (66 nm where each run fits at 2 nm) with only a note about repeated stamps."""
    from hyst_model.io.bag import _one_run

    t, u, y = _stage(600)
    t2, u2, y2 = _stage(400, seed=1)
    both = np.r_[t, t2[:300]]
    order = np.argsort(both, kind="stable")  # what sorting by stamp makes of them
    r = Record(both[order], np.r_[u, u2[:300]][order], np.r_[y + 1e-7, y2[:300]][order])
    with pytest.raises(DataError, match="300 samples share their time stamp with another of different values"):
        regularise(r)
    ns = (np.r_[t, t2] * 1e9).astype(np.int64) + 1_700_000_000_000_000_000  # in the order a recorder got them
    with pytest.raises(DataError, match="start over at message 601 of 1000"):
        _one_run("bag", "/stage/state", ns)
    swapped = ns[:600].copy()
    swapped[[10, 11]] = swapped[[11, 10]]  # one run with delivery reordering: sorted, not refused
    _one_run("bag", "/stage/state", swapped)
