"""regularise: lockstep duplicates collapsed, realtime missed periods bridged or split (issue 11)."""
import numpy as np
import pytest

from hyst_model.errors import DataError
from hyst_model.io.record import Record, regularise

DT = 5e-4


def _rec(n=400, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    return Record(t, rng.uniform(0, 100, n), np.sin(2 * np.pi * 5 * t) * 1e-6, {"source": "x.mcap"})


def _drop(rec, idx):
    keep = np.ones(len(rec), bool)
    keep[idx] = False
    return Record(rec.t[keep], rec.u[keep], rec.y[keep], dict(rec.meta))


def test_lockstep_duplicates_collapsed_and_reported():
    r = _rec()
    t = np.r_[np.zeros(7), r.t]
    u = np.r_[np.full(7, r.u[0]), r.u]
    y = np.r_[np.full(7, r.y[0]), r.y]
    out, notes = regularise(Record(t, u, y, {"source": "b"}))
    out.check()
    assert len(out) == len(r) and out.meta["regularised"]["duplicates"] == 7
    assert any("collapsed 7" in n for n in notes)


def test_short_gaps_bridged_u_held_y_interpolated():
    r = _rec()
    g = _drop(r, [100, 101, 250])
    out, notes = regularise(g, "auto")
    out.check()
    assert len(out) == len(r) and out.meta["regularised"]["bridged_samples"] == 3
    assert out.u[100] == out.u[101] == r.u[99]  # held
    np.testing.assert_allclose(out.y, r.y, atol=1e-8)  # smooth y interpolated closely
    assert any("bridged 2 gap" in n for n in notes)


def test_long_gap_split_keeps_longest_and_short_ones_bridged():
    r = _rec()
    g = _drop(r, list(range(100, 150)) + [300])
    out, notes = regularise(g, "auto")
    out.check()
    assert out.t[0] == pytest.approx(150 * DT) and len(out) == 250
    assert any("long gap" in n for n in notes)
    full, _ = regularise(g, "bridge")
    assert len(full.check()) == len(r)
    lon, _ = regularise(g, "longest")
    assert len(lon.check()) == 150  # 150..299


def test_refuse_suggests_the_option_and_backwards_stamps_refused():
    g = _drop(_rec(), [100])
    with pytest.raises(DataError, match="--gaps auto"):
        regularise(g, "refuse")
    r = _rec()
    r.t[50] = r.t[10]
    with pytest.raises(DataError, match="backwards"):
        regularise(r)


def test_regular_record_unchanged():
    r = _rec()
    out, notes = regularise(r)
    assert notes == [] and np.array_equal(out.t, r.t)
