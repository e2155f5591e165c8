"""A drift the base absorbs: the refit also starts from the drift read off the record alone (Drift.record_start).

Generated GMA stage 7200145 (a staircase over part of the range, a linear drift of 35× the noise): the base fitted
without the drift put δ1 and δ2 on their bound 1, its residual showed no trend, and every refit of mbw+drift from
the residual's start stayed at 13× the noise floor — the diagnosis named dynamics and called the rest outside the
library.
"""
from __future__ import annotations

import numpy as np
import pytest

from hyst_common.profiles import GMA
from hyst_model.diagnose.diagnose import diagnose
from hyst_model.diagnose.refit import _scales, default_fitter, refit, rmse, validation_mask
from hyst_model.effects import compose
from hyst_model.effects.drift import Drift
from hyst_model.spec import build_model
from hyst_sim.generator import generate_case


@pytest.fixture(scope="module")
def case():
    return generate_case(7200145, "single_large", excitations="alt")


def _base(c):
    cfg = dict(_scales(c.u, c.y), dt=c.t[1] - c.t[0])
    bm = build_model("mbw", (), cfg)
    return cfg, bm, default_fitter(bm, c.t, c.u, c.y, None)


def test_the_drift_refit_reaches_the_floor_only_with_the_record_start(case, monkeypatch):
    cfg, bm, th_b = _base(case)
    val = validation_mask(case.t.size, case.u)
    _, _, yh = refit(bm, ["drift"], cfg, case.t, case.u, case.y, th_b)
    assert rmse((case.y - yh)[val]) < 1.2 * case.noise
    monkeypatch.setattr(Drift, "record_start", lambda self, t, u, y, scored: None)
    _, _, yh0 = refit(bm, ["drift"], cfg, case.t, case.u, case.y, th_b)
    assert rmse((case.y - yh0)[val]) > 5 * case.noise            # the residual's start alone stays in the basin


def test_the_record_start_reads_the_drift_the_base_hides(case):
    cfg, bm, th_b = _base(case)
    m = compose(bm, ["drift"], cfg)
    scored = ~validation_mask(case.t.size, case.u)
    truth = case.forms[0][1] * 0.05 * GMA.stroke * np.arange(1, 6) / 5   # the generator's drift_lin at the knots
    rec = m.effects[0].record_start(case.t, case.u, case.y, scored)
    from_residual = m.start(case.t, case.u, case.y, th_b)[-5:]
    got = np.array([rec[f"c{j}"] for j in range(1, 6)])
    assert np.max(np.abs(got - truth)) < 0.5 * truth[-1]
    assert np.max(np.abs(from_residual - truth)) > 0.5 * truth[-1]   # the residual's start does not see it


def test_undo_output_inverts_the_drift_and_record_starts_replace_only_that_effect(case):
    cfg, bm, th_b = _base(case)
    m = compose(bm, ["delay", "drift"], cfg)
    d = m.effects[1]
    te = np.array([1e-8, -2e-8, 3e-8, 0.0, 5e-9])
    y = np.linspace(0.0, 1e-6, case.t.size)
    assert np.allclose(d.undo_output(te, case.t, case.u, d.output(te, case.t, case.u, y)), y, rtol=0, atol=1e-18)
    scored = ~validation_mask(case.t.size, case.u)
    th0 = m.start(case.t, case.u, case.y, th_b)
    (alt,) = m.record_starts(case.t, case.u, case.y, th0, scored)
    changed = np.flatnonzero(alt != th0)
    assert changed.size and all(m.names[i].startswith("drift.") for i in changed)
    assert m.record_starts(case.t, case.u, case.y, th0, scored, skip=("drift",)) == []


def test_a_record_that_never_moves_gives_no_record_start(case):
    d = compose(build_model("mbw", (), dict(_scales(case.u, case.y), dt=5e-4)), ["drift"], {}).effects[0]
    flat = np.full(case.t.size, 1.0)
    assert d.record_start(case.t, flat, case.y, np.ones(case.t.size, bool)) is None


def test_the_diagnosis_names_the_drift(case):
    d = diagnose(case.t, case.u, case.y, jobs=1)
    assert d.missing == "drift" and d.ladder[-1].rmse < 1.2 * d.noise


def test_no_record_start_where_the_record_shows_no_drift(case):
    cfg, bm, _ = _base(case)
    d = compose(bm, ["drift"], cfg).effects[0]
    scored = ~validation_mask(case.t.size, case.u)
    comp = case.forms[0][1] * 0.05 * GMA.stroke * (case.t - case.t[0]) / (case.t[-1] - case.t[0])
    assert d.record_start(case.t, case.u, case.y, scored) is not None
    assert d.record_start(case.t, case.u, case.y - comp, scored) is None     # the same stage without its drift


def test_an_effect_whose_record_start_fails_leaves_the_refit_from_its_own_start(case, monkeypatch):
    cfg, bm, th_b = _base(case)

    def broken(self, t, u, y, scored):
        raise np.linalg.LinAlgError("singular")
    monkeypatch.setattr(Drift, "record_start", broken)
    val = validation_mask(case.t.size, case.u)
    _, th, yh = refit(bm, ["drift"], cfg, case.t, case.u, case.y, th_b)
    assert np.all(np.isfinite(th)) and rmse((case.y - yh)[val]) > 5 * case.noise   # the residual start's basin


def test_hyst_fits_fast_method_starts_from_the_record_start_too(case, monkeypatch):
    from hyst_model import identify
    val = validation_mask(case.t.size, case.u)
    cfg = dict(_scales(case.u, case.y), dt=case.t[1] - case.t[0])

    def fitted_rmse() -> float:
        m = build_model("mbw", ["drift"], cfg)
        res = identify.fit(m, case.t, case.u, case.y, method="fast", split=val)
        return rmse((case.y - m.simulate(res.theta, case.t, case.u))[val])
    assert fitted_rmse() < 1.2 * case.noise                           # what hyst diagnose's refit reaches
    monkeypatch.setattr(Drift, "record_start", lambda self, t, u, y, scored: None)
    assert fitted_rmse() > 5 * case.noise
