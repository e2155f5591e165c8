"""Simulated plant against known answers: exact MBW with effects off, each effect's signature, clipping."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hyst_model.core import pea_default
from hyst_sim.errors import ConfigError, SimError
from hyst_sim.plant import CLIP_NONFINITE, CLIP_RANGE, CLIP_SLEW, Plant, PlantConfig
from hyst_common.profiles import GMA, PEA

DT = 1e-3
BASE = PlantConfig(pea_default(), dt=DT)  # no sensor effects, no slew limit


def _step_input(n=12000, k0=100, v=75.0):
    u = np.zeros(n)
    u[k0:] = v
    return u


def _sine(n=3000, f=5.0, dt=DT):
    t = np.arange(n) * dt
    return 75.0 - 75.0 * np.cos(2 * np.pi * f * t)


def test_effects_off_is_exactly_the_mbw_model():
    u = _sine()
    plant = Plant(BASE)
    np.testing.assert_array_equal(plant.run(u).y, pea_default().simulate(u))
    plant.reset()
    np.testing.assert_array_equal([plant.step(v).y for v in u], pea_default().simulate(u))


def test_default_plant_is_pea_with_2nm_sensor_and_reproducible():
    plant = Plant.default(rate=2000.0, seed=3)
    assert plant.dt == 5e-4 and plant.config.effects.active() == ("noise", "quantization")
    u = np.full(4000, 150.0)
    a = plant.run(u)
    assert abs(a.x[-1] - 30e-6) < 0.05e-6                       # 150 V held reads 30 um
    assert np.allclose(a.y / 2e-9, np.round(a.y / 2e-9), atol=1e-6)  # 2 nm quantisation
    assert 1.7e-9 < np.std(a.y[2000:] - a.x[2000:]) < 2.5e-9        # 2 nm noise (+ quantisation)
    plant.reset()
    b = [plant.step(v) for v in u]
    np.testing.assert_array_equal(a.y, [r.y for r in b])           # run() == repeated step(), seeded
    other = Plant.default(rate=2000.0, seed=4).run(u).y
    assert not np.array_equal(a.y, other)


def test_all_effects_on_step_equals_run_and_reset_repeats():
    cfg = BASE.with_strengths(creep=0.01, asymmetry=0.02, dynamics=800.0, delay=2, drift=3e-9,
                              saturation=0.05, noise=2e-9, quantization=2e-9).replace(slew_max=5e4)
    plant = Plant(cfg)
    u = np.concatenate([_sine(1500, 7.0), [np.nan, 1e9, -np.inf], _sine(500, 20.0)])
    a = plant.run(u)
    plant.reset()
    b = [plant.step(v) for v in u]
    np.testing.assert_array_equal(a.y, [r.y for r in b])
    np.testing.assert_array_equal(a.u_applied, [r.u_applied for r in b])
    assert np.all(np.isfinite(a.y))


def test_creep_grows_linearly_in_log_time_after_a_step():
    gamma = 0.012
    u = _step_input(n=30100)
    y0 = Plant(BASE).run(u).y
    d = Plant(BASE.with_strengths(creep=gamma)).run(u).y - y0
    step = y0[-1] - y0[50]
    t = np.array([0.1, 1.0, 10.0, 29.9])
    v = d[100 + np.round(t / DT).astype(int)]
    per_decade = np.diff(v[:3])
    np.testing.assert_allclose(per_decade, gamma * step, rtol=0.08)  # same increase in each decade
    # a single first-order lag would give a much smaller increment in the later decade
    assert per_decade[1] / per_decade[0] > 0.85
    assert v[3] > v[2]                                                # still creeping after 10 s
    assert abs(d[50]) == 0.0                                          # no creep before the step (at rest)


def test_delay_shifts_the_response_by_n_samples():
    u = _sine(2000, 10.0)
    y0 = Plant(BASE).run(u).y
    for n in (1, 3, 7):
        y = Plant(BASE.with_strengths(delay=n)).run(u).y
        np.testing.assert_array_equal(y[n:], y0[:-n])
        assert np.all(y[:n] == y0[0])


def test_dynamics_ring_at_the_resonance_and_keep_the_static_gain():
    fn, cfg = 350.0, BASE.replace(dt=1 / 20000.0)
    cfg = cfg.replace(effects=cfg.effects.with_effects(
        dynamics=type(cfg.effects.dynamics)(strength=fn, damping=0.04)))
    u = _step_input(n=20000, k0=200, v=75.0)
    y0 = Plant(BASE.replace(dt=1 / 20000.0)).run(u).y
    y = Plant(cfg).run(u).y
    e = (y - y0)[201:4000]
    crossings = np.flatnonzero(np.diff(np.sign(e)) != 0)
    f_est = 1.0 / (2 * np.mean(np.diff(crossings)) / 20000.0)
    assert abs(f_est / (fn * math.sqrt(1 - 0.04**2)) - 1) < 0.03
    assert np.max(y) > y0[-1] + 0.5 * (y0[-1] - y0[0])          # lightly damped: big overshoot
    assert abs(y[-1] - y0[-1]) < 1e-12                          # unit DC gain


def test_asymmetry_is_an_even_bow_zero_at_the_stroke_ends():
    beta = 0.03
    plant = Plant(BASE.with_strengths(asymmetry=beta))
    lo, hi = plant.stroke_range
    u = np.linspace(0, 150, 301).repeat(200)
    x0 = Plant(BASE).run(u).y
    x = plant.run(u).y
    bow = x - x0
    q = (x0 - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
    np.testing.assert_allclose(bow, -beta * (hi - lo) * (1 - q * q), atol=1e-15)
    assert abs(bow[0]) < 1e-12 and abs(bow[-1]) < 1e-3 * (hi - lo)
    assert np.min(bow) == pytest.approx(-beta * (hi - lo), rel=1e-2)


def test_saturation_flattens_the_top_smoothly_and_never_exceeds_the_limit():
    s = 0.06
    u = np.concatenate([np.linspace(0, 150, 3000), np.full(2000, 150.0), np.linspace(150, 0, 3000)])
    x0 = Plant(BASE).run(u).y
    plant = Plant(BASE.with_strengths(saturation=s))
    lo, hi = plant.stroke_range
    x = plant.run(u).y
    assert np.max(x) < hi - s * (hi - lo)
    assert hi - np.max(x) > 1.1 * s * (hi - lo)
    low = x0 < hi - 3 * s * (hi - lo)                           # below the knee: untouched
    np.testing.assert_array_equal(x[low], x0[low])
    assert np.min(x) == np.min(x0)                              # a PEA saturates at the top only
    g = Plant(PlantConfig.for_profile("gma", 1000.0, sensor=False).with_strengths(saturation=s))
    xg = g.run(np.concatenate([np.full(1000, 5.0), np.full(1000, -5.0)])).y
    glo, ghi = g.stroke_range
    assert xg[999] < ghi - s * (ghi - glo) and xg[-1] > glo + s * (ghi - glo)   # both ends for the GMA


def test_drift_is_independent_of_the_input_and_has_the_set_rate():
    r = 4e-9
    cfg = BASE.replace(effects=BASE.effects.with_effects(
        drift=type(BASE.effects.drift)(strength=r, sine=0.0, walk=0.0)))
    ua, ub = _sine(20000, 2.0), np.zeros(20000)
    da = Plant(cfg).run(ua).y - Plant(BASE).run(ua).y
    db = Plant(cfg).run(ub).y - Plant(BASE).run(ub).y
    np.testing.assert_allclose(da, db, atol=1e-18)
    slope = np.polyfit(np.arange(20000) * DT, da, 1)[0]
    assert slope == pytest.approx(r, rel=1e-6)
    walk = Plant(BASE.with_strengths(drift=r)).run(ub).y - Plant(BASE).run(ub).y
    # the default shape adds a random walk: increments of walk·r·√dt RMS (the trend and the slow sine add ~r·dt)
    walk_rms = type(BASE.effects.drift)().walk * r * np.sqrt(DT)
    assert walk_rms > 0 and np.std(np.diff(walk)) == pytest.approx(walk_rms, rel=0.05)


def test_noise_and_quantisation_have_the_set_size():
    cfg = BASE.with_strengths(noise=5e-9)
    y = Plant(cfg).run(np.full(20000, 60.0)).y
    x = Plant(BASE).run(np.full(20000, 60.0)).y
    assert np.std(y - x) == pytest.approx(5e-9, rel=0.03)
    yq = Plant(BASE.with_strengths(quantization=10e-9)).run(_sine(500)).y
    np.testing.assert_allclose(yq / 10e-9, np.round(yq / 10e-9), atol=1e-6)
    assert len(np.unique(yq)) > 50


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3)),
                min_size=1, max_size=60),
       st.sampled_from(["pea", "gma"]))
def test_clipping_never_leaves_the_profile_and_flags_every_change(cmds, profile):
    cfg = PlantConfig.for_profile(profile, 1000.0)
    plant = Plant(cfg)
    prof = PEA if profile == "pea" else GMA
    out = plant.run(np.array(cmds, dtype=float))
    assert np.all((out.u_applied >= prof.v_min) & (out.u_applied <= prof.v_max))
    prev = np.concatenate([[cfg.v_init], out.u_applied[:-1]])
    assert np.all(np.abs(out.u_applied - prev) <= cfg.slew_max * cfg.dt * (1 + 1e-12))
    cmd = np.array(cmds, dtype=float)
    nonfinite = ~np.isfinite(cmd)
    assert np.all((out.flags & CLIP_NONFINITE).astype(bool) == nonfinite)
    assert np.all(out.u_applied[nonfinite] == prev[nonfinite])
    unchanged = (out.flags == 0)
    np.testing.assert_array_equal(out.u_applied[unchanged], cmd[unchanged])
    assert np.all(np.isfinite(out.y))


def test_clip_flags_name_the_reason():
    plant = Plant(BASE.replace(slew_max=1000.0))                   # 1 V per sample
    assert plant.step(0.5)[1:3] == (0.5, False)
    r = plant.step(100.0)
    assert r.u_applied == 1.5 and r.clipped
    out = plant.run([-5.0, np.nan, 1.2, 3.0])
    assert list(out.flags) == [CLIP_RANGE | CLIP_SLEW, CLIP_NONFINITE, 0, CLIP_SLEW]
    assert list(out.u_applied) == [0.5, 0.5, 1.2, 2.2]


def test_switching_an_effect_on_mid_run_keeps_the_state_without_a_jump():
    plant, twin = Plant(BASE), Plant(BASE)
    u = _sine(700)
    plant.run(u)
    twin.run(u)
    plant.reconfigure(BASE.with_strengths(creep=0.02, dynamics=500.0, delay=2))
    hold = plant.u_applied
    a, b = plant.run(np.full(5, hold)).y, twin.run(np.full(5, hold)).y
    assert np.max(np.abs(a - b)) < 0.1e-6 < 1e-6 < abs(a[0] - Plant(BASE).step(hold).y)  # state carried over
    assert plant.time == pytest.approx(0.705)
    plant.reconfigure(BASE)                                     # and back: the stage continues as before
    np.testing.assert_allclose(plant.run(u[:300]).y, twin.run(u[:300]).y, atol=2e-9)


def test_bad_configurations_are_refused_with_a_reason():
    with pytest.raises(ConfigError, match="effects.delay"):
        BASE.with_strengths(delay=-1)
    with pytest.raises(ConfigError, match="integer"):
        BASE.with_strengths(delay=1.5)
    with pytest.raises(ConfigError, match="effects.creep"):
        BASE.with_strengths(creep=float("nan"))
    with pytest.raises(ConfigError, match="unknown effect"):
        BASE.with_strengths(backlash=1.0)
    with pytest.raises(ConfigError, match="v_init"):
        BASE.replace(v_init=200.0)
    with pytest.raises(ConfigError, match="diverges|rest displacement"):
        Plant(BASE.replace(mbw=pea_default().replace(delta1=1.5)))
    with pytest.raises(ConfigError, match="outside"):
        Plant(BASE).reset(-1.0)


def test_a_diverging_state_raises_instead_of_publishing_nan():
    plant = Plant(BASE)
    plant._st[0] = np.inf  # simulate a numerically broken state
    with pytest.raises(SimError, match="diverged"):
        plant.step(10.0)


@pytest.mark.parametrize("profile", ["pea", "gma"])
def test_alternating_full_range_input_stays_on_the_end_stops_and_is_flagged(profile):
    """0/150 V alternating every sample drove the unbounded stage to −0.4 mm in 10 samples and −724 m in 80."""
    from hyst_sim.plant import STOP_MARGIN, PlantConfig
    cfg = PlantConfig.for_profile(profile, 2000.0, seed=0).replace(slew_max=1e9)
    plant = Plant(cfg)
    plant.reset()
    lo, hi = plant.stroke_range
    span = hi - lo
    r = plant.run(np.tile([cfg.v_min, cfg.v_max], 2000))
    assert np.all(np.isfinite(r.y))
    quant = 1e-8
    assert r.y.min() >= lo - STOP_MARGIN * span - quant and r.y.max() <= hi + STOP_MARGIN * span + quant
    assert r.at_stop.sum() > 100 and not r.clipped.any()        # a legal input: a stop, not a clip
    # the stage recovers: a slow sine afterwards is within the stroke and never on a stop
    t = np.arange(4000) / 2000.0
    r2 = plant.run(cfg.v_min + (cfg.v_max - cfg.v_min) * (0.5 + 0.5 * np.sin(2 * np.pi * 2 * t)))
    assert not r2.at_stop[2000:].any()


def test_a_resonance_driven_at_its_frequency_stays_within_the_stops_and_is_flagged():
    """The stops held only the hysteresis: a 350 Hz mode driven at resonance (0-115 V, nothing clipped) swung the
    published position to -67..+73 µm on a 30 µm stroke, and nothing was flagged."""
    from hyst_sim.plant import STOP_MARGIN, PlantConfig
    rate = 2000.0
    cfg = PlantConfig.for_profile("pea", rate, sensor=False).with_strengths(dynamics=350.0)
    plant = Plant(cfg)
    lo, hi = plant.stroke_range
    span = hi - lo
    t = np.arange(int(2 * rate)) / rate
    u = 75 * np.minimum(t / 0.05, 1) + 40 * np.minimum(t / 0.2, 1.0) * np.sin(2 * np.pi * 350 * t)
    r = plant.run(u)
    assert r.x.min() >= lo - STOP_MARGIN * span - 1e-12 and r.x.max() <= hi + STOP_MARGIN * span + 1e-12
    assert r.at_stop.sum() > 100 and not r.clipped.any()


def test_ordinary_excitations_never_touch_the_stops():
    plant = Plant.default(rate=2000.0, seed=1)
    plant.reset()
    t = np.arange(40000) / 2000.0
    for f_hz in (1.0, 10.0, 100.0):
        r = plant.run(75.0 + 75.0 * np.sin(2 * np.pi * f_hz * t))
        assert not r.at_stop.any()


def test_drift_switched_off_and_on_again_does_not_bring_its_old_offset_back():
    """Off, the offset leaves the reading (the user asked so); on again, the reading jumped by the old offset."""
    from hyst_sim.plant import PlantConfig
    cfg = PlantConfig.for_profile("pea", 1000.0, sensor=False).with_strengths(drift=1e-7)
    plant = Plant(cfg)
    plant.reset()
    plant.run(np.full(5000, 75.0))
    plant.reconfigure(cfg.with_strengths(drift=0.0))
    off = plant.run(np.full(10, 75.0)).y[-1]
    plant.reconfigure(cfg.with_strengths(drift=1e-7))
    assert abs(plant.run(np.full(2, 75.0)).y[0] - off) < 20e-9  # one sample of drift and its sine, not 748 nm
