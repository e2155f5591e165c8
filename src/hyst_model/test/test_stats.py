"""Known-answer tests of hyst_model.diagnose.stats (fit figures, segments, residual correlation tests)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hyst_model.diagnose import stats as S


def test_fit_figures_known_values():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    f = S.fit_figures(y, y)
    assert f.rmse == 0 and f.fit_percent == pytest.approx(100.0) and f.max_abs == 0
    f = S.fit_figures(y, np.full(4, y.mean()))  # the mean predictor scores 0 %
    assert f.fit_percent == pytest.approx(0.0, abs=1e-12)
    f = S.fit_figures(y, y - 0.5)  # constant error
    assert f.rmse == pytest.approx(0.5) and f.bias == pytest.approx(0.5)
    assert f.nrmse == pytest.approx(0.5 / 3.0)
    assert f.fit_percent == pytest.approx(100 * (1 - 1.0 / np.sqrt(5.0)))
    with pytest.raises(ValueError):
        S.fit_figures(y, y[:3])


def test_noise_sigma_on_sine_plus_noise():
    rng = np.random.default_rng(1)
    t = np.arange(20000) / 2000.0
    x = 10 * np.sin(2 * np.pi * 1.0 * t) + 0.05 * rng.standard_normal(t.size)
    assert S.noise_sigma(x) == pytest.approx(0.05, rel=0.1)


def _staircase_and_sines(fs=1000.0, noise=0.002, seed=0):
    rng = np.random.default_rng(seed)
    parts = [np.zeros(int(fs)), np.full(int(fs), 5.0)]
    ts = np.arange(int(3 * fs)) / fs
    parts.append(5 + 4 * np.sin(2 * np.pi * 2.0 * ts))
    ts = np.arange(int(2 * fs)) / fs
    parts.append(5 + 4 * np.sin(2 * np.pi * 10.0 * ts))
    u = np.concatenate(parts) + noise * rng.standard_normal(sum(p.size for p in parts))
    return np.arange(u.size) / fs, u


def test_segment_input_finds_holds_step_and_sines_by_frequency():
    t, u = _staircase_and_sines()
    segs = S.segment_input(t, u)
    kinds = [s.kind for s in segs]
    assert kinds[0] == "hold" and segs[0].stop == pytest.approx(1000, abs=2)
    assert "step" in kinds
    step = segs[kinds.index("step")]
    assert step.start == pytest.approx(1000, abs=2) and step.level == pytest.approx(5.0, abs=0.01)
    sines = [s for s in segs if s.kind == "sine"]
    assert [round(s.freq, 1) for s in sines] == [2.0, 10.0]
    assert sines[0].start >= 2000 and sines[1].stop == pytest.approx(t.size, abs=60)
    # covering and contiguous
    assert segs[0].start == 0 and segs[-1].stop == t.size
    assert all(a.stop == b.start for a, b in zip(segs, segs[1:]))


def test_fit_by_segment_localises_the_error():
    t, u = _staircase_and_sines()
    y = 1e-6 * u
    yhat = y.copy()
    yhat[t > 5.0] += 1e-8 * np.sin(2 * np.pi * 10 * t[t > 5.0])  # wrong only during the 10 Hz sine
    by = {s.label.split(" ")[0] + (f"{s.freq:.0f}" if s.kind == "sine" else ""): s for s in
          S.fit_by_segment(t, u, y, yhat)}
    assert by["sine10"].fit.rmse == pytest.approx(1e-8 / np.sqrt(2), rel=0.05)
    assert by["sine2"].fit.rmse == 0.0 and by["hold"].fit.rmse == 0.0


def test_fit_by_branch_and_level():
    t = np.arange(4000) / 1000.0
    u = 75 + 75 * np.sin(2 * np.pi * t)
    y = u * 2e-7
    du = np.diff(u, prepend=u[0])
    du[0] = du[1]
    yhat = y - np.where(du > 0, 1e-7, 0.0)  # error on the rising branch only
    br = S.fit_by_branch(u, y, yhat)
    assert br["rising"].rmse == pytest.approx(1e-7) and br["falling"].rmse == 0.0 and br["hold"].n == 0
    yhat = y - 1e-9 * u ** 2 / 150  # error grows with level
    lv = S.fit_by_level(u, y, yhat, n_levels=3)
    assert [lo for lo, _, _ in lv] == pytest.approx([0, 50, 100], abs=1e-6)
    r = [f.rmse for _, _, f in lv]
    assert r[0] < r[1] < r[2]


def test_fit_by_band_parseval_and_location():
    fs, n = 1000.0, 10000
    t = np.arange(n) / fs
    y = np.sin(2 * np.pi * 3 * t)
    e = 0.01 * np.sin(2 * np.pi * 100 * t) + 0.002
    bands = S.fit_by_band(y, y - e, fs)
    rms = np.array([b.rmse for b in bands])
    assert np.sum(rms ** 2) == pytest.approx(np.mean(e ** 2), rel=1e-9)
    hit = [b for b in bands if b.f_lo <= 100 < b.f_hi][0]
    assert hit.rmse == pytest.approx(0.01 / np.sqrt(2), rel=1e-6)
    assert bands[0].rmse == pytest.approx(0.002, rel=1e-6)  # the bias sits in the DC band


def test_whiteness_white_vs_coloured():
    rng = np.random.default_rng(3)
    w = rng.standard_normal(20000)
    a = S.autocorr(w, 25)
    assert a.values[0] == pytest.approx(1.0)
    assert a.bound == pytest.approx(2.5758 / np.sqrt(w.size), rel=1e-3)
    assert not a.significant and a.frac_outside <= 0.08
    ar = np.empty_like(w)
    ar[0] = w[0]
    for k in range(1, w.size):
        ar[k] = 0.8 * ar[k - 1] + w[k]
    c = S.autocorr(ar, 25)
    assert c.significant and c.values[1] == pytest.approx(0.8, abs=0.03)


def test_crosscorr_sign_lag_and_bound():
    rng = np.random.default_rng(4)
    u = rng.standard_normal(20000)
    e = 0.3 * np.roll(u, 5) + rng.standard_normal(u.size)  # residual follows the input 5 samples later
    c = S.crosscorr(e, u, 25)
    assert c.significant and c.lag_at_max == 5 and c.values[c.lags == 5][0] > 0.2
    ind = S.crosscorr(rng.standard_normal(u.size), u, 25)
    assert not ind.significant
    # A slowly varying input and residual widen the bound (P > 1) compared with white data.
    slow_u = np.convolve(u, np.ones(50) / 50, mode="same")
    slow_e = np.convolve(rng.standard_normal(u.size), np.ones(50) / 50, mode="same")
    assert S.crosscorr(slow_e, slow_u, 25).bound > 3 * ind.bound


def test_higher_order_tests_catch_even_terms_the_linear_test_misses():
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 20000)
    e = 0.5 * (u ** 2 - np.mean(u ** 2)) + 0.05 * rng.standard_normal(u.size)  # an asymmetric (even) error
    assert not S.crosscorr(e, u, 10).significant
    ho = S.higher_order_tests(e, u, 10)
    assert ho["e_u2"].significant and ho["e_u2"].lag_at_max == 0 and ho["e_u2"].max_abs > 0.9
    e2 = 0.5 * np.abs(np.diff(u, prepend=u[0])) + 0.05 * rng.standard_normal(u.size)  # speed-dependent error
    ho2 = S.higher_order_tests(e2 - e2.mean(), u, 10)
    assert ho2["e_absdu"].significant and ho2["e_absdu"].lag_at_max == 0
    clean = S.higher_order_tests(0.05 * rng.standard_normal(u.size), u, 10)
    assert not any(c.significant for c in clean.values())


def test_compare_stats_json_and_lag_step():
    t, u = _staircase_and_sines()
    y = 1e-6 * u
    yhat = y + 1e-8
    cs = S.compare_stats(t, u, y, yhat)
    d = json.loads(json.dumps(cs.to_dict(values=True)))
    assert d["overall"]["rmse"] == pytest.approx(1e-8)
    assert d["lag_step"] >= 1 and len(d["whiteness"]["values"]) == 26
    assert {"e2_u", "e_u2", "e_absdu", "e2_u2"} == set(d["higher_order"])
    with pytest.raises(ValueError, match="non-finite"):
        S.compare_stats(t, u, y, np.where(t > 1, np.nan, yhat))
    # 2 Hz dominant input at 1 kHz, 7000 samples: lags span about a quarter period of the strongest line
    assert cs.lag_step == 5  # a quarter period (125 samples) over 25 lags


def test_harmonics_of_a_periodic_residual():
    rng = np.random.default_rng(6)
    fs, f = 2000.0, 1.0
    t = np.arange(int(3 * fs)) / fs
    e = 3e-8 * np.sin(2 * np.pi * 5 * f * t) + 1e-8 * np.cos(2 * np.pi * 2 * f * t + 0.3)
    amp, share = S.harmonics(t, e + 1e-8 * rng.standard_normal(t.size), f)
    assert amp[4] == pytest.approx(3e-8, rel=0.02) and amp[1] == pytest.approx(1e-8, rel=0.06)
    assert share == pytest.approx(5e-16 / (5e-16 + 1e-16), rel=0.05)  # periodic power / total power
    amp0, share0 = S.harmonics(t, 1e-8 * rng.standard_normal(t.size), f)
    assert share0 < 0.01


def test_ringing_after_a_step():
    rng = np.random.default_rng(7)
    fs = 5000.0
    t = np.arange(1000) / fs
    e = 1e-6 * np.exp(-t / 0.01) * np.sin(2 * np.pi * 950 * t) + 2e-8 * rng.standard_normal(t.size)
    r = S.ringing(t, e, noise=2e-8)
    assert r is not None and r[0] == pytest.approx(950, abs=30)
    assert S.ringing(t, 2e-8 * rng.standard_normal(t.size), noise=2e-8) is None
    # a slow creep-like drift is not ringing
    assert S.ringing(t, 1e-6 * np.log1p(t / 1e-3), noise=2e-8) is None


def test_broadband_input_is_one_segment_and_not_a_hold():
    rng = np.random.default_rng(8)
    fs, n = 750.0, 8192
    U = np.zeros(n // 2 + 1, complex)
    f = np.fft.rfftfreq(n, 1 / fs)
    band = (f >= 5) & (f <= 150)
    U[band] = np.exp(2j * np.pi * rng.random(band.sum()))
    u = np.fft.irfft(U, n)
    u *= 50 / u.std()
    t = np.arange(n) / fs
    segs = S.segment_input(t, u)
    assert [s.kind for s in segs] == ["broadband"]
    br = S.fit_by_branch(u, u, u)
    assert br["hold"].n < 0.05 * n and br["rising"].n > 0.4 * n


def test_spectral_peaks_find_a_resonance_line_not_the_trend():
    rng = np.random.default_rng(9)
    fs = 5000.0
    n = 50000
    t = np.arange(n) / fs
    trend = np.cumsum(rng.standard_normal(n)) * 1e-3  # 1/f² background
    line = 0.05 * np.sin(2 * np.pi * 970.0 * t + 0.1 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n))
    peaks = S.spectral_peaks(trend + line + 0.01 * rng.standard_normal(n), fs)
    assert peaks and abs(peaks[0][0] - 970.0) < 3.0
    assert S.spectral_peaks(trend + 0.01 * rng.standard_normal(n), fs) == []
    # harmonics of a drive can be excluded
    assert S.spectral_peaks(trend + line, fs, exclude=(970.0,)) == []


def test_noisy_measured_input_still_segments_by_frequency():
    rng = np.random.default_rng(10)
    fs = 2000.0
    t = np.arange(int(8 * fs)) / fs
    u = 75 + 70 * np.sin(2 * np.pi * np.where(t < 4, 1.0, 3.0) * t) + 0.5 * rng.standard_normal(t.size)
    sines = [s for s in S.segment_input(t, u) if s.kind == "sine"]
    assert [round(s.freq, 2) for s in sines] == [1.0, 3.0]
