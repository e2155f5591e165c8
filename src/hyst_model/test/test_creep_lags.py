"""Creep as two lags with free time constants (``creep.form: lags``): its law, its start, its fit, its file."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from hyst_model.core import pea_default
from hyst_model.diagnose.diagnose import diagnose
from hyst_model.diagnose.refit import _scales, refit, rmse, validation_mask
from hyst_model.effects import EFFECTS, compose
from hyst_model.effects.creep import TAUS, _lags_start
from hyst_model.errors import EffectError
from hyst_model.io.params_file import read_params, spec_from_model, write_params
from hyst_model.model import MBWModel

DT = 1e-3


def test_a_step_creeps_by_the_two_lags_exactly():
    """After a step Δ the output falls short by gain·Δ, less what the lags take in the step's own sample, and the
    rest arrives through the two lags (held input: the lags' discretisation is exact)."""
    c = EFFECTS["creep"]({"dt": DT, "creep.form": "lags"})
    g, t1, t2, sh = 0.08, 0.05, 0.9, 0.7
    t = np.arange(4000) * DT
    x = np.where(np.arange(t.size) >= 10, 2e-6, 0.0)
    y = c.output(np.array([g, t1, t2, sh]), t, None, x)
    k = np.arange(t.size - 10) + 1  # samples since the step, counting the step's own
    want = 2e-6 * (1 - g * (sh * np.exp(-DT / t1) ** k + (1 - sh) * np.exp(-DT / t2) ** k))
    np.testing.assert_allclose(y[10:], want, rtol=0, atol=1e-18)
    assert np.all(y[:10] == 0.0)


def test_an_unknown_form_is_refused():
    with pytest.raises(EffectError, match="creep.form"):
        EFFECTS["creep"]({"dt": DT, "creep.form": "powerlaw"})


def _record(seed: int = 4, taus=(0.08, 2.5), shares=(0.5, 0.5), k: float = 0.12):
    """A PEA record (steps with holds, then sines) whose creep is two lags with static gain — the stage's output
    grows towards (1 + k) × the hysteresis, written here with scipy, not with the library's operator."""
    rng = np.random.default_rng(seed)
    t = np.arange(16000) * DT
    levels = rng.uniform(10.0, 140.0, 8)
    u = np.repeat(levels, 1000)
    tt = t[8000:] - t[8000]
    u = np.r_[u, 75.0 - 60.0 * np.cos(2 * np.pi * 0.7 * tt) * np.exp(-tt / 20.0)]
    x = pea_default().simulate(u)
    y = x.copy()
    for tau, w in zip(taus, shares):
        a = np.exp(-DT / tau)
        y += k * w * lfilter([1 - a], [1, -a], x - x[0])
    noise = 2e-9
    return t, u, y + rng.normal(0.0, noise, t.size), noise


def test_the_start_finds_the_pair_of_lags_the_residual_holds():
    t, u, y, _ = _record()
    x = pea_default().simulate(u)
    c = EFFECTS["creep"]({"dt": DT, "creep.form": "lags"})
    th = np.array([0.1, 0.08, 2.5, 0.5])
    r = c.output(th, t, u, x) - x
    s = _lags_start(t, x, r)
    near = {float(TAUS[np.argmin(np.abs(np.log(TAUS / v)))]) for v in (0.08, 2.5)}
    assert {s["tau1"], s["tau2"]} == near, s
    assert s["gain"] > 0 and 0 <= s["share"] <= 1


def test_diagnose_finds_creep_that_settles_where_the_log_law_cannot():
    """Creep that settles within seconds (two lags): diagnose names creep, in the lags form, at the noise, with
    the time constants; the log law's power-law weights over 0.01-300 s, refitted on the same base, stay well
    above the noise (they leave a slow ramp that reads as drift)."""
    t, u, y, noise = _record()
    d = diagnose(t, u, y)
    assert d.missing == "creep", d.explanation
    m, th = d.models[d.ladder[-1].model]
    p = dict(zip(m.names, th))
    assert m.name == "mbw+creep" and m.effects[0].form == "lags"
    assert d.ladder[-1].rmse < 1.5 * noise, [(r.model, r.rmse) for r in d.ladder]
    taus = sorted((p["creep.tau1"], p["creep.tau2"]))
    assert taus[0] == pytest.approx(0.08, rel=0.25) and taus[1] == pytest.approx(2.5, rel=0.25), p
    bm, th_b = d.models[d.base]
    val = validation_mask(t.size, u)
    _, _, yh = refit(bm, ["creep"], {**_scales(u, y), "dt": DT, "creep.form": "log"}, t, u, y, th_b)
    assert rmse((y - yh)[val]) > 3 * noise


def test_the_form_and_the_time_constants_go_through_a_params_file(tmp_path):
    t, u, _, _ = _record()
    m = compose(MBWModel(u_scale=15.0, y_scale=5.42e-6), ["creep"], {"dt": DT, "creep.form": "lags"})
    th = m.theta0.copy()
    th[:8] = pea_default().vector
    for k, v in {"creep.gain": 0.06, "creep.tau1": 0.05, "creep.tau2": 1.5, "creep.share": 0.3}.items():
        th[m.names.index(k)] = v
    path = write_params(tmp_path / "p.yaml", spec_from_model(m, th, dt=DT))
    spec = read_params(path)
    assert spec.config["creep.form"] == "lags"
    m2 = compose(MBWModel(u_scale=15.0, y_scale=5.42e-6), ["creep"], spec.config)
    th2 = np.array([spec.values[n] for n in m2.names])
    np.testing.assert_array_equal(m2.simulate(th2, t, u), m.simulate(th, t, u))


def test_the_lags_time_constants_stay_within_a_third_of_the_scored_span():
    """A lag slower than the record shows only the ramp its response starts with, which drift explains as well:
    the lags form's time constants are bounded by a third of the span the fit scores (the record's configuration),
    and the start keeps to it."""
    t, u, y, _ = _record()
    scored = np.ones(t.size, bool)
    scored[12000:] = False  # the fit scores the first 12 s
    cfg = EFFECTS["creep"].data_config(t, u, y, scored)
    assert cfg["creep.tau_max"] == pytest.approx((t[11999] - t[0]) / 3.0)
    c = EFFECTS["creep"]({"dt": DT, "creep.form": "lags", **cfg})
    hi = {p.name: p.upper for p in c.params()}
    assert hi["tau1"] == hi["tau2"] == cfg["creep.tau_max"]
    x = pea_default().simulate(u)
    slow = EFFECTS["creep"]({"dt": DT, "creep.form": "lags"}).output(np.array([0.1, 0.2, 60.0, 0.3]), t, u, x)
    s = c.start(t, u, slow, slow - x)
    assert max(s["tau1"], s["tau2"]) <= cfg["creep.tau_max"], s
    with pytest.raises(EffectError, match="tau_max"):
        EFFECTS["creep"]({"dt": DT, "creep.form": "lags", "creep.tau_max": 1e4})
