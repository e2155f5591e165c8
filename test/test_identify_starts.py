"""The base fit and the delay search on generated stages where they used to fail (issue #10).

Fixed seeds of the generator (hyst_sim.generator), not the repo's own bags: MBW records without any effect
whose equation-error starts all led to a wrong basin (5-25x the noise floor), and sub-sample output and input
delays on steps that the base imitated with its δ terms (named ``dynamics`` before).
"""
import numpy as np
import pytest

from hyst_model.diagnose.diagnose import SPLIT, _scales, default_fitter, diagnose, validation_mask
from hyst_model.spec import build_model
from hyst_sim.generator import generate_case


def _held_out_base_error(c) -> float:
    """RMSE (m) on the held-out samples of the base MBW fitted as ``hyst diagnose`` fits it (scales, split)."""
    cfg = dict(_scales(c.u, c.y), dt=float(c.t[1] - c.t[0]))
    m = build_model("mbw", (), cfg)
    th = default_fitter(m, c.t, c.u, c.y, None)
    val = validation_mask(c.t.size, c.u)
    e = (c.y - m.simulate(th, c.t, c.u))[val]
    return float(np.sqrt(np.mean(e * e)))


@pytest.mark.parametrize("seed", [100033, 100118, 100178])
def test_base_fit_reaches_the_noise_floor_on_mbw_truths(seed):
    c = generate_case(seed, "none")
    assert _held_out_base_error(c) < 1.3 * c.noise, f"split {SPLIT}"


@pytest.mark.parametrize("seed,shapes", [(2500001, "wide")])
def test_every_start_is_probed_before_the_best_go_on(seed, shapes, monkeypatch):
    """The equation-error ranking can put the start that reaches the noise floor behind others (accuracy seed 7:
    9th of 18 on 700057 and 700117, both false alarms): every start runs a few iterations first. Since the offset
    scan and the bounded regression those two rank right; of 300 effect-free generated records this one still
    needs the probe. Without it (the first n_starts starts in equation-error order, as before) the fit stays off."""
    from hyst_model.identify.fast import FastFit
    from hyst_model.identify.memo import FitMemo
    c = generate_case(seed, "none", shapes=shapes)
    cfg = dict(_scales(c.u, c.y), dt=float(c.t[1] - c.t[0]))
    m = build_model("mbw", (), cfg)
    val = validation_mask(c.t.size, c.u)

    def err() -> float:
        monkeypatch.setattr(FastFit, "SOLVES", FitMemo(16))  # no fit remembered from the other run
        th = default_fitter(m, c.t, c.u, c.y, None)
        e = (c.y - m.simulate(th, c.t, c.u))[val]
        return float(np.sqrt(np.mean(e * e)))

    assert err() < 1.1 * c.noise
    # before: the first n_starts in equation-error order, and the declared defaults (listed last)
    monkeypatch.setattr(FastFit, "_probe", lambda self, problem, starts: (starts[: self.n_starts] + starts[-1:], 0))
    assert err() > 1.2 * c.noise


@pytest.mark.slow
@pytest.mark.parametrize("seed,kind", [(100004, "single_small"), (100029, "single_small"),
                                       (100039, "single_large"), (100048, "single_large")])
def test_sub_sample_delays_on_steps_are_named_delay(seed, kind):
    c = generate_case(seed, kind)
    assert c.expected == ("delay",)
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "delay", d.explanation


def test_interleaved_hold_out_is_never_scored_in_training():
    """split=mask: corrupting the held-out samples changes nothing in the fit, only the validation figure."""
    from hyst_model import identify
    from hyst_model.identify import block_mask
    c = generate_case(100009, "none")
    cfg = dict(_scales(c.u, c.y), dt=float(c.t[1] - c.t[0]))
    m = build_model("mbw", (), cfg)
    mask = block_mask(c.t.size, 0.25, 8, c.u)
    assert mask[-1] and not mask[0] and abs(mask.mean() - 0.25) < 0.01
    y2 = c.y.copy()
    y2[mask] += 5e-6
    r1 = identify.fit(m, c.t, c.u, c.y, split=mask)
    r2 = identify.fit(m, c.t, c.u, y2, split=mask)
    np.testing.assert_allclose(r1.theta, r2.theta, rtol=1e-9, atol=1e-15)
    assert r1.rmse < 1.3 * c.noise < 5e-6 < r2.rmse
    assert "interleaved" in r1.split


def test_sweep_tail_no_longer_extrapolated():
    """A log sweep's tail holds its highest frequencies: validated there, an MBW truth was called 650x the noise."""
    c = generate_case(100021, "none")
    d = diagnose(c.t, c.u, c.y, effects=["drift"])
    assert d.missing == "none", d.explanation


def test_base_fit_reaches_the_noise_floor_on_a_stage_with_fast_memory():
    """A generated MBW stage unlike the thesis's (shapes "wide": loop twice as wide, δ1 = 0.901, δ2 = 0.93, a pole
    near 30 Hz at 2 kHz), effect-free, on a few sines: the equation-error regression on the low-passed output
    landed far from it, every start ended at ≥ 3.9x the noise floor, and the diagnosis answered 'unexplained'.
    The regression on the output itself recovers it, and the fit reaches the floor."""
    c = generate_case(1800004, "none", shapes="wide")
    assert _held_out_base_error(c) < 1.3 * c.noise


@pytest.mark.parametrize("seed,shapes", [(2200070, "thesis"), (2200163, "wide"), (2200178, "wide"),
                                         (2300013, "wide"), (2300048, "wide")])
def test_base_fit_reaches_the_noise_floor_where_the_equation_error_starts_missed(seed, shapes):
    """Effect-free generated records whose base fits ended at 27-195x the noise floor (the truth, inside the bounds,
    sits at it). Three causes, each fixed in :func:`~hyst_model.identify.equation_error.equation_error_starts` or
    the bounds: 2200070 (a piezo driven at 54-98 V) has its offset, the reading at 0 V, 15 µm below every reading,
    outside the offsets searched; 2200163 and 2200178 have input memories longer than their output's (δ2 > δ1), so
    ζ1 is 2.0 and 1.2 in the data's units, beyond Table 3.1's 0.9; and the regression clipped each coefficient to
    its bound on its own, which breaks ψ1 + α1 when ν keeps one sign (only their sum is then seen)."""
    c = generate_case(seed, "none", shapes=shapes)
    assert _held_out_base_error(c) < 1.3 * c.noise


@pytest.mark.parametrize("rate", [True, False])
def test_offset_scan_equals_the_regression_at_each_offset(rate):
    """The one-sweep offset scan gives the same normal equations as building them at each offset."""
    from hyst_model.identify.equation_error import _ee_normal, _ee_normal_scan
    rng = np.random.default_rng(3)
    y0 = np.cumsum(rng.normal(size=800))
    y1 = y0 + rng.normal(size=800)
    u0, u1 = rng.normal(size=800), rng.normal(size=800)
    cs = np.sort(np.concatenate([rng.uniform(y0.min() - 5, y0.max() + 5, 30), y0[:3]]))  # also exactly on rows
    G, b, yy = _ee_normal_scan(y0, y1, u0, u1, cs, 0.93, 2.5, rate)
    for i, c in enumerate(cs):
        G1, b1, yy1 = _ee_normal(y0, y1, u0, u1, c, 0.93, 2.5, rate)
        np.testing.assert_allclose(G[i], G1, rtol=1e-9, atol=1e-9 * np.abs(G1).max())
        np.testing.assert_allclose(b[i], b1, rtol=1e-9, atol=1e-9 * np.abs(b1).max())
        assert yy[i] == pytest.approx(yy1, rel=1e-9)


def test_delay_start_on_a_stage_with_long_memory_is_the_delay_not_the_last_tap():
    """Generated wide-shape piezo stage (δ1 = 0.97), sensor delay of about 13.5 samples on band-limited noise: the
    ridge FIR response was smeared by the stage's own memory and peaked at its last tap (39.6 samples), the joint
    fit stayed at 12.8 ms and 51x the noise floor, and the diagnosis named a mode. The last tap is no longer taken
    for a peak; the equation-error lag search finds the delay."""
    from hyst_model.effects.delay import Delay, _fir_delay
    c = generate_case(2000038, "single_large", shapes="wide")
    dt = float(c.t[1] - c.t[0])
    assert _fir_delay(c.u, c.y, 40) is None
    d = Delay({"dt": dt, "u_scale": 15.0, "y_scale": 5e-6, "delay.side": "output"})
    tau = d.start(c.t, c.u, c.y, np.zeros_like(c.y))["tau"] / dt
    assert 12.5 <= tau <= 14.5

