"""The delay effect on either side of the hysteresis, and its start from the data's own impulse response."""
import numpy as np
import pytest

from hyst_model.core import pea_default
from hyst_model.effects import compose
from hyst_model.effects.delay import Delay, _fir_delay
from hyst_model.errors import EffectError
from hyst_model.spec import build_model

DT = 5e-4


def _steps(seed: int, n: int = 8000) -> np.ndarray:
    """Voltage steps with holds of 50-300 samples (jumps within one sample, as a DAC applies them)."""
    rng = np.random.default_rng(seed)
    u, k = np.empty(n), 0
    while k < n:
        h = int(rng.integers(50, 300))
        u[k:k + h] = rng.uniform(0.0, 150.0)
        k += h
    return u


def _record(seed: int, tau_samples: float, side: str):
    u = _steps(seed)
    t = np.arange(u.size) * DT
    tau = tau_samples * DT
    x = pea_default().simulate(np.interp(t - tau, t, u, left=u[0]) if side == "input" else u)
    y = np.interp(t - tau, t, x, left=x[0]) if side == "output" else x
    return t, u, y + 2e-9 * np.random.default_rng(seed + 1).standard_normal(u.size)


def test_side_is_configuration_and_round_trips():
    cfg = {"dt": DT, "u_scale": 15.0, "y_scale": 5e-6}
    assert Delay(cfg).kind == "input"
    d = Delay({**cfg, "delay.side": "output"})
    assert d.kind == "output" and {v["delay.side"] for v in Delay.variants()} == {"input", "output"}
    base = build_model("mbw", (), cfg)
    m = compose(base, [Delay({**cfg, "delay.side": "output"})])
    assert m.config()["delay.side"] == "output"
    with pytest.raises(EffectError, match="delay.side"):
        Delay({**cfg, "delay.side": "sideways"})


def test_output_side_shifts_the_output_not_the_input():
    t = np.arange(400) * DT
    u = np.where(t > 0.05, 100.0, 0.0)
    cfg = {"dt": DT, "u_scale": 15.0, "y_scale": 5e-6}
    d = Delay({**cfg, "delay.side": "output"})
    y = np.linspace(0, 1, t.size)
    np.testing.assert_allclose(d.output(np.array([3 * DT]), t, u, y)[3:], y[:-3], rtol=1e-12)


@pytest.mark.parametrize("side", ["input", "output"])
@pytest.mark.parametrize("tau", [0.0, 0.3, 2.0, 6.5])
def test_fir_start_finds_fractional_and_whole_sample_delays_on_steps(side, tau):
    t, u, y = _record(3, tau, side)
    est = _fir_delay(u, y, 40)
    assert est is not None
    # an input-side fraction is seen through the hysteresis' nonlinear same-sample response: a start, refined
    # by the joint fit (see the diagnose test below), so a looser bound there
    assert est == pytest.approx(tau, abs=0.1 if side == "output" else 0.15)


def test_fir_start_declines_on_smooth_input():
    t = np.arange(8000) * DT
    u = 75 + 70 * np.sin(2 * np.pi * 1.0 * t)
    y = pea_default().simulate(u)
    assert _fir_delay(u, y, 40) is None


def test_start_is_remembered_by_the_record_and_only_by_it():
    """The start depends on the record alone, so a diagnosis's many delay refits reuse it: the same τ as computed
    afresh, and another record (one sample changed) is computed anew."""
    from hyst_model.effects import delay as dmod
    t, u, y = _record(5, 3.4, "output")
    cfg = {"dt": DT, "u_scale": 15.0, "y_scale": 5e-6}
    d = Delay({**cfg, "delay.side": "output"})
    hits = dmod._FIR_MEMO.hits
    first = d.start(t, u, y, np.zeros_like(y))
    again = d.start(t, u, y, np.zeros_like(y))
    assert dmod._FIR_MEMO.hits == hits + 1 and again == first
    assert first["tau"] == pytest.approx(3.4 * DT, abs=0.1 * DT)
    dt = float(np.median(np.diff(t)))  # as the start reads it
    assert first["tau"] == float(np.clip(_fir_delay(u, y, 40) * dt, 0.0, d.params()[0].upper))
    y2 = y.copy()
    y2[4000] += 1e-6  # another record: not served from the memo
    d.start(t, u, y2, np.zeros_like(y))
    assert dmod._FIR_MEMO.hits == hits + 1


@pytest.mark.parametrize("side", ["input", "output"])
def test_diagnose_names_a_sub_sample_delay_on_steps(side):
    from hyst_model.diagnose.diagnose import diagnose
    t, u, y = _record(11, 0.3, side)
    d = diagnose(t, u, y, effects=["delay", "dynamics", "creep", "drift"])
    assert d.missing == "delay", d.explanation
    assert d.candidates[0].params["delay.tau"] == pytest.approx(0.3 * DT, abs=0.15 * DT)


def _band_limited(seed: int, tau_samples: float, n: int = 16000):
    """Band-limited noise (0.05 fs) through the default PEA, the output delayed by ``tau_samples``: the FIR
    regression of Δy on Δu is ill-conditioned there (neighbouring lags nearly alike)."""
    from scipy.signal import butter, sosfiltfilt
    rng = np.random.default_rng(seed)
    w = sosfiltfilt(butter(4, 0.1, output="sos"), rng.standard_normal(n))
    u = 75.0 + 60.0 * w / np.max(np.abs(w))
    t = np.arange(n) * DT
    x = pea_default().simulate(u)
    y = np.interp(t - tau_samples * DT, t, x, left=x[0])
    return t, u, y + 2e-9 * np.random.default_rng(seed + 1).standard_normal(n)


def _fir_condition(u: np.ndarray, lags: int = 40) -> float:
    du = np.diff(u)
    X = np.lib.stride_tricks.sliding_window_view(np.concatenate([np.zeros(lags), du]), lags + 1)[:, ::-1]
    G = X.T @ X
    d = np.sqrt(np.diag(G))
    return float(np.linalg.cond(G / np.outer(d, d)))


@pytest.mark.parametrize("seed", [1, 2])
def test_fir_start_on_band_limited_noise_is_regularised_not_refused(seed):
    from hyst_model.effects.delay import FIR_COND_MAX
    t, u, y = _band_limited(seed, 14.3)
    assert _fir_condition(u) > FIR_COND_MAX  # the regularised path, where the start used to come from the residual
    assert _fir_delay(u, y, 40) == pytest.approx(14.3, abs=0.5)


def test_undo_output_advances_an_output_delay_and_stops_at_an_effect_it_cannot_undo():
    from hyst_model.effects.compose import around_effects
    cfg = {"dt": DT, "u_scale": 15.0, "y_scale": 5e-6, "delay.side": "output"}
    t = np.arange(600) * DT
    u = 75 + 60 * np.sin(2 * np.pi * 5 * t)
    x = np.sin(2 * np.pi * 3 * t)
    d = Delay(cfg)
    th = np.array([4.4 * DT])
    back = d.undo_output(th, t, u, d.output(th, t, u, x))
    np.testing.assert_allclose(back[1:-5], x[1:-5], atol=1e-4)  # interpolated twice: a slight smoothing
    assert Delay({**cfg, "delay.side": "input"}).undo_output(th, t, u, x) is None
    base = build_model("mbw", (), cfg)
    m = compose(base, ["asymmetry", "delay"], cfg)  # the delay outermost: undone; the bow inside it cannot be
    theta = m.theta0.copy()
    theta[m.names.index("delay.tau")] = 4.0 * DT
    uu, yy = around_effects(m, theta, t, u, x)
    assert uu is u
    np.testing.assert_allclose(yy[:-4], x[4:], rtol=1e-12)
    m2 = compose(base, ["delay", "creep"], cfg)  # creep outermost: nothing is undone
    uu, yy = around_effects(m2, m2.theta0, t, u, x)
    assert uu is u and yy is x


@pytest.mark.slow
def test_fit_reaches_the_noise_floor_with_a_long_output_delay_on_band_limited_noise():
    """``hyst fit --effects delay`` (output side): the base refitted on the record advanced by the start delay
    first. From the base fitted to the record as it is (its δ terms imitate part of the delay) the joint fit
    stopped at a shorter delay, above the noise."""
    from hyst_model.identify import fit
    t, u, y = _band_limited(1, 14.3)
    cfg = {"dt": DT, "delay.side": "output"}
    from hyst_model.models import data_config
    base = build_model("mbw", (), {**data_config(u, y), **cfg})
    m = compose(base, ["delay"], {**data_config(u, y), **cfg})
    r = fit(m, t, u, y, method="fast")
    assert m.unpack(r.theta)["delay.tau"] / DT == pytest.approx(14.3, abs=0.3)
    assert r.rmse < 1.3 * 2e-9, r.rmse


@pytest.mark.parametrize("side", ["input", "output"])
@pytest.mark.parametrize("tau", [0.0, 7.0, 13.4])
def test_equation_error_lag_finds_the_delay_of_an_mbw_record(side, tau):
    """Known answer: the default PEA on band-limited noise, delayed on either side; the lag whose shifted record an
    MBW equation-error start fits best in free run is the delay (integer part exact, the fraction within half)."""
    from hyst_model.identify.lag import equation_error_lag
    rng = np.random.default_rng(5)
    from scipy.signal import butter, sosfiltfilt
    w = sosfiltfilt(butter(4, 0.05, output="sos"), rng.standard_normal(12000))
    u = 75.0 + 60.0 * w / np.max(np.abs(w))
    t = np.arange(u.size) * DT
    x = pea_default().simulate(np.interp(t - tau * DT, t, u, left=u[0]) if side == "input" else u)
    y = (np.interp(t - tau * DT, t, x, left=x[0]) if side == "output" else x) + 2e-9 * rng.standard_normal(u.size)
    lag, prof = equation_error_lag(u, y, 40)
    assert lag == pytest.approx(tau, abs=0.5)
    assert np.nanmin(prof) < 0.2 * np.nanmax(prof)  # a clear dip, not a flat profile


def test_lag_search_on_a_long_record_uses_its_busiest_stretch():
    from hyst_model.identify.lag import _busiest_window
    u = np.zeros(30000)
    u[21000:21400] = np.sin(np.linspace(0, 40, 400))
    w = _busiest_window(u, 1000)
    assert w.stop - w.start == 1000 and w.start <= 21000 and 21400 <= w.stop
    assert _busiest_window(u[:800], 1000) == slice(0, 800)
