"""Per-sample effect inverses (controllers) against the effects' own batch simulation: exact known answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hyst_model.core import pea_default
from hyst_model.core.mbw import mbw_simulate
from hyst_model.effects import EFFECTS
from hyst_model.effects.online import MBWStepper, OnlineEffect
from hyst_model.models import BASE_MODELS

DT = 5e-4
CFG = {"dt": DT, "u_scale": 15.0, "y_scale": 5.42e-6}


def _record(n: int = 6000, seed: int = 0):
    """A base-model output under steps and a sine (SI), with its input."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = 75 + 40 * np.sin(2 * np.pi * 3 * t) + np.repeat(rng.uniform(-30, 30, n // 500 + 1), 500)[:n]
    m = pea_default()
    x = m.y_scale * mbw_simulate(np.ascontiguousarray(m.vector), u / m.u_scale) + m.offset
    return t, u, x


def _recover(inv: OnlineEffect, y: np.ndarray, u: np.ndarray) -> np.ndarray:
    inv.reset(float(y[0]), float(u[0]))
    return np.array([inv.measure(float(a), float(b)) for a, b in zip(y, u)])


@pytest.mark.parametrize("gain,tilt", [(0.02, 0.0), (0.08, 0.2), (-0.03, -0.1)])
def test_creep_inverse_recovers_the_displacement_exactly(gain, tilt):
    t, u, x = _record()
    x = x - x[0] + 1e-6  # at rest at the start, as the lags assume
    eff = EFFECTS["creep"](CFG)
    y = eff.output(np.array([gain, tilt]), t, u, x)
    assert np.max(np.abs(y - x)) > 1e-8  # the creep is really there
    inv = eff.online(np.array([gain, tilt]))
    inv.reset(float(x[0]), float(u[0]))
    xr = np.array([inv.measure(float(a), float(b)) for a, b in zip(y, u)])
    assert np.max(np.abs(xr - x)) < 1e-12
    # target() is the same inverse without advancing the lags: what measure() would answer from this state,
    # and asked twice, the same answer
    import copy
    yn, un = float(y[-1]) + 1e-7, float(u[-1]) + 5.0
    first = inv.target(yn, un)
    assert first == pytest.approx(copy.deepcopy(inv).measure(yn, un), abs=1e-15)
    assert abs(first - yn) > 1e-10  # the lags' part was removed
    assert inv.target(yn, un) == first


def test_asymmetry_inverse_recovers_the_displacement_exactly():
    t, u, x = _record()
    eff = EFFECTS["asymmetry"](CFG)
    eff.u_c, eff.y_c = 75.0, float(np.mean(x))
    theta = np.array([0.03, -0.04])
    y = eff.output(theta, t, u, x)
    assert np.max(np.abs(y - x)) > 1e-8
    xr = _recover(eff.online(theta), y, u)
    assert np.max(np.abs(xr - x)) < 1e-12


def test_saturation_inverse_exact_inside_and_limited_beyond():
    t, u, x = _record()
    eff = EFFECTS["saturation"](CFG)
    span = float(x.max() - x.min())
    theta = np.array([x.max() - 0.1 * span, x.min() - span, 0.2 * span])
    y = eff.output(theta, t, u, x)
    inv = eff.online(theta)
    xr = _recover(inv, y, u)
    inside = (y - (theta[0] - theta[2])) / theta[2] < inv.REACH  # within the invertible part of the knee
    assert inside.mean() > 0.9
    assert np.max(np.abs(xr[inside] - x[inside])) < 1e-12
    lo, hi = inv.bounds()
    assert hi < theta[0] and math.isinf(lo)
    assert math.isfinite(inv.target(theta[0] + 1e-3, 0.0)) and inv.limited == 1


@pytest.mark.parametrize("side", ["input", "output"])
def test_delay_smith_predictor_sees_the_undelayed_stage(side):
    """On a perfect model the predictor's value is the undelayed base output, whatever the delay."""
    t, u, x = _record(4000)
    cfg = dict(CFG, **{"delay.side": side})
    eff = EFFECTS["delay"](cfg)
    tau = 7.4 * DT
    m = pea_default()
    base = BASE_MODELS["mbw"](CFG)
    theta_b = base.pack(m.to_dict())
    if side == "input":
        y = base.simulate(theta_b, t, eff.input(np.array([tau]), t, u))
    else:
        y = eff.output(np.array([tau]), t, u, base.simulate(theta_b, t, u))
    inv = eff.online(np.array([tau]), base=lambda: MBWStepper(m))
    assert inv.preview == pytest.approx(tau)
    inv.reset(float(y[0]), float(u[0]))
    xr = np.array([inv.measure(float(a), float(b)) for a, b in zip(y, u)])
    x_now = base.simulate(theta_b, t, u)
    assert np.max(np.abs(y - x_now)) > 1e-8
    assert np.max(np.abs(xr - x_now)) < 1e-9


def test_effects_without_online_form_say_why():
    for name, cfg in (("dynamics", {"dynamics.structure": "feedback"}), ("dynamics", {"dynamics.hold": "foh"})):
        eff = EFFECTS[name](dict(CFG, **cfg))
        assert eff.online(np.array([p.default for p in eff.params()]), base=lambda: MBWStepper(pea_default())) is None
        assert len(eff.online_note) > 20


def test_drift_observer_estimates_the_offset_from_the_sensor():
    """A ramp plus a step of the sensor offset on a perfect base model: the estimate follows it without a steady
    lag (an offset-and-rate filter; a first-order observer kept r·τ = 2 nm behind this ramp), target and
    measurement both lose it, and a bad sample is refused."""
    from hyst_model.effects.drift import OBSERVER_TAU, DriftObserver

    t, u, x = _record()
    d = 40e-9 * t + np.where(t > 1.0, 30e-9, 0.0)  # 40 nm/s and a 30 nm jump at 1 s
    obs = EFFECTS["drift"](CFG).online(np.zeros(5), base=lambda: MBWStepper(pea_default()))
    assert isinstance(obs, DriftObserver) and obs.needs_sensor and obs.follow_reading
    obs.reset(float(x[0] + d[0]), float(u[0]))
    est = np.empty_like(t)
    for k, (yk, uk) in enumerate(zip(x + d, u)):
        obs.observe(obs.measure(float(yk), float(uk)), float(uk))
        est[k] = obs.offset
    late = t > 1.0 + 8 * OBSERVER_TAU  # settled after the jump
    np.testing.assert_allclose(est[late], d[late], atol=0.3e-9)
    assert abs(obs.slope * 2000.0 - 40e-9) < 1e-9  # the ramp's rate, per sample at 2 kHz
    assert obs.target(5e-6, 75.0) == pytest.approx(5e-6 - obs.offset)
    before = obs.offset
    obs.measure(float("nan"), 75.0)
    obs.observe(float("nan"), 75.0)
    assert obs.offset == before


@pytest.mark.parametrize("theta", [[350.0, 0.04, 1.0, 0.0], [800.0, 0.1, 1.0, 0.0], [150.0, 0.5, 1.0, 0.0],
                                   [350.0, 0.04, 0.4, 0.0], [150.0, 0.02, 0.9, 0.0], [300.0, 0.05, 0.3, 0.5],
                                   [120.0, 0.3, 0.5, 0.0, 400.0, 0.3], [100.0, 0.05, 0.2, 0.0, 180.0, 0.05]])
def test_series_resonance_inverse_and_predictor_are_exact_on_the_model(theta):
    """target() inverts the ZOH resonance exactly (filtering the targets gives the reference back), and with the
    base model exact the measurement is the base output itself — also for a mode only part of the motion
    passes (participation < 1), for a sensor that samples into the hold (lag > 0), and for two modes in cascade
    behind one hold (``dynamics.modes: 2``, the four-state system) whose sampled zeros lie inside the unit
    circle."""
    from hyst_model.effects.dynamics import SeriesResonanceInverse, series_filter

    t, u, _ = _record(3000)
    m = pea_default()
    st = MBWStepper(m)  # the base output from rest, as the predictor runs it
    st.reset(float(u[0]))
    x = np.array([st.step(float(v)) for v in u])
    th = np.array(theta)
    fn, zeta, part, lag = theta[:4]
    second = (theta[4], theta[5]) if len(theta) == 6 else None
    eff = EFFECTS["dynamics"]({**CFG, "dynamics.modes": 2 if second else 1})

    def reading(xx):  # the stage's reading under the base output xx
        return xx + part * (series_filter(xx, fn, zeta, DT, "zoh", lag, second) - xx)
    y = reading(x)
    assert np.max(np.abs(y - x)) > 1e-8
    np.testing.assert_allclose(y, eff.output(th, t, u, x), rtol=0, atol=1e-15)
    inv = eff.online(th, base=lambda: MBWStepper(m))
    assert isinstance(inv, SeriesResonanceInverse), eff.online_note
    inv.reset(float(y[0]), float(u[0]))
    xr = np.array([inv.measure(float(a), float(b)) for a, b in zip(y, u)])
    assert np.max(np.abs(xr - x)) < 1e-15 + 1e-9 * float(np.max(np.abs(x)))
    # feedforward: a smooth reference through the inverse, then through the resonance, is the reference
    r = x + 1e-7 * np.sin(2 * np.pi * 7 * t)
    inv2 = eff.online(th, base=lambda: MBWStepper(m))
    inv2.reset(float(r[0]), float(u[0]))
    xt = []
    for k in range(r.size):
        xt.append(inv2.target(float(r[k]), float(u[k])))
        inv2._s = inv2._A @ inv2._s + inv2._B * xt[-1]  # the stage achieved the target
    assert np.max(np.abs(reading(np.array(xt))[1:] - r[1:])) < 1e-12


@pytest.mark.parametrize("theta", [[350.0, 0.04, 1.0, 0.0, 600.0, 0.05], [583.0, 0.09, 1.0, 0.56, 980.0, 0.68]])
def test_two_modes_whose_sampled_zero_leaves_the_unit_circle_are_refused_with_the_reason(theta):
    """A lightly damped cascade the whole motion passes has a sampled zero outside the unit circle at 2 kHz
    (|z| 6.9 and 31.6 here; the second set is what the diagnosis once fitted on a delayed 583 Hz stage): no
    per-sample inverse, said in the note the controllers report."""
    eff = EFFECTS["dynamics"]({**CFG, "dynamics.modes": 2})
    assert eff.online(np.array(theta), base=lambda: MBWStepper(pea_default())) is None
    assert "second at" in eff.online_note and "unit circle" in eff.online_note


@pytest.mark.parametrize("lag,match", [(1.0, "feed-through"), (0.3, "unit circle")])
def test_series_resonance_read_into_the_hold_may_have_no_inverse(lag, match):
    """With the whole motion through the mode and the sensor a period into the hold (lag 1, the textbook ZOH) the
    reading does not respond to x_k at all; at 0.3 of a period it does, but the sampled zero lies outside the
    unit circle (|z| 2.5 at 350 Hz, 2 kHz; stability.resonance_tf gives the same zero): both refused with the
    reason, never a diverging inverse. At lag 1 the reading is the lag-0 mode one sample later: the effect inverts
    it as that (reference previewed one sample); at 0.3 it has no per-sample form and says why (the controllers
    report it and still check their gains against the mode)."""
    from hyst_model.effects.dynamics import SeriesResonanceInverse

    with pytest.raises(ValueError, match=match):
        SeriesResonanceInverse(350.0, 0.04, CFG["dt"], lambda: MBWStepper(pea_default()), 1.0, lag)
    eff = EFFECTS["dynamics"](CFG)
    inv = eff.online(np.array([350.0, 0.04, 1.0, lag]), base=lambda: MBWStepper(pea_default()))
    if lag == 1.0:
        assert isinstance(inv, SeriesResonanceInverse) and inv.preview == pytest.approx(CFG["dt"])
    else:
        assert inv is None
        assert match in eff.online_note and "gains are still checked" in eff.online_note


@pytest.mark.parametrize("name,cfg,theta", [
    ("asymmetry", {}, [0.03, -0.04]),
    ("asymmetry", {"form": "kink"}, [0.3, 5e-6]),
    ("saturation", {"two_sided": True}, None),
])
def test_static_forward_predictions_are_the_effects_own_maps(name, cfg, theta):
    """The chain prediction (:meth:`OnlineEffect.forward`) of a static effect is the batch model's output for the
    same input, on both streams, and undoes the effect's measurement inverse."""
    t, u, x = _record()
    eff = EFFECTS[name]({**CFG, **cfg})
    if name == "asymmetry" and not cfg:
        eff.u_c, eff.y_c = 75.0, float(np.mean(x))
    if theta is None:  # a limit 20 % inside the record's range at each end, a knee of 10 %
        lo, hi = float(np.min(x)), float(np.max(x))
        span = hi - lo
        theta = [hi - 0.2 * span, lo + 0.2 * span, 0.1 * span]
    theta = np.array(theta, dtype=float)
    y = eff.output(theta, t, u, x)
    assert np.max(np.abs(y - x)) > 1e-8  # the effect is really there
    on = eff.online(theta)
    assert on.predictive and not on.smith
    fz = np.array([on.forward(float(a), float(a), float(b), True) for a, b in zip(x, u)])
    np.testing.assert_allclose(fz[:, 0], y, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(fz[:, 0], fz[:, 1])
    back = np.array([on.forward(on.measure(float(a), float(b)), 0.0, float(b), True)[0] for a, b in zip(y, u)])
    lo, hi = on.bounds()  # saturation: a reading past REACH of the knee is held there, not inverted
    inside = (y > lo) & (y < hi)
    assert inside.mean() > 0.8
    np.testing.assert_allclose(back[inside], y[inside], rtol=0, atol=1e-12)


def test_drift_side_says_what_drifts_and_only_the_sensor_side_leaves_the_reference_alone():
    """``drift.side``: ``stage`` (default, what a file without the key means) removes the estimate from measurement
    and reference (the reading follows the reference); ``sensor`` from the measurement only (the position does),
    and needs no reading in open loop. Anything else is refused; identification is the same for both."""
    from hyst_model.effects.drift import DriftObserver
    from hyst_model.errors import EffectError

    stage, sensor = EFFECTS["drift"](CFG), EFFECTS["drift"](dict(CFG, **{"drift.side": "sensor"}))
    assert stage.config()["side"] == "stage" and sensor.config()["side"] == "sensor"
    t, u, x = _record()
    th = np.array([1e-9, -2e-9, 3e-9, 0.0, 5e-9])
    np.testing.assert_array_equal(stage.output(th, t, u, x), sensor.output(th, t, u, x))
    obs = sensor.online(np.zeros(5), base=lambda: MBWStepper(pea_default()))
    assert isinstance(obs, DriftObserver) and not obs.follow_reading and not obs.needs_sensor
    obs.reset(float(x[0]), float(u[0]))
    for yk, uk in zip(x + 50e-9, u):  # a 50 nm sensor offset (the record's own start settles within 1 s)
        obs.observe(obs.measure(float(yk), float(uk)), float(uk))
    assert obs.offset == pytest.approx(50e-9, abs=0.3e-9)
    assert obs.target(5e-6, 75.0) == 5e-6 and obs.measure(6e-6, 75.0) == pytest.approx(6e-6 - obs.offset)
    with pytest.raises(EffectError, match="drift.side must be one of stage, sensor"):
        EFFECTS["drift"](dict(CFG, **{"drift.side": "amplifier"}))
