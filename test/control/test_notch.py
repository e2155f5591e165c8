"""The PID command notch (hyst_control.notch): the filter against its definition, the PID running it bumplessly,
the stability check with it, and the guard's notch on a stage with a lightly damped mode — in the loop."""
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import lfilter

from hyst_bringup.loop import SimPlant, run_closed_loop
from hyst_control.controllers import make_controller
from hyst_control.errors import ConfigError
from hyst_control.notch import Notch, notch_tf
from hyst_control.pid import PID, PIDGains
from hyst_control.loop_tf import _mu_max
from hyst_control.stability import (MODE_TOLERANCE, Resonance, check_loop, closed_loop_poles, controller_tf, guard,
                                    notched, plant_tf)
from hyst_model.core import pea_default

DT = 5e-4


def _gain(num, den, f, dt=DT):
    q = np.exp(-2j * math.pi * f * dt)
    return abs(np.polyval(num[::-1], q) / np.polyval(den[::-1], q))


@pytest.mark.parametrize(("fn", "zz", "zp"), [(350.0, 0.04, 1.0), (120.0, 0.01, 0.3), (800.0, 0.2, 0.5)])
def test_the_notch_is_unity_at_dc_and_zeta_zero_over_zeta_pole_at_its_frequency(fn, zz, zp):
    """Prewarped bilinear: the continuous notch's depth ζz/ζp lands exactly at fn; unit gain at DC and far away."""
    num, den = notch_tf(fn, zz, zp, DT)
    assert den[0] == 1.0
    assert num.sum() / den.sum() == pytest.approx(1.0, abs=1e-12)
    assert _gain(num, den, fn) == pytest.approx(zz / zp, rel=1e-9)
    assert _gain(num, den, fn / 20) == pytest.approx(1.0, abs=0.02 * zp)
    assert max(_gain(num, den, f) for f in np.linspace(0, 0.5 / DT, 2001)) <= 1.0 + 1e-9  # it only removes


def test_the_notch_refuses_what_the_rate_cannot_hold():
    for fn, zz, zp in ((0.0, 0.1, 1.0), (0.95 * 0.5 / DT, 0.1, 1.0), (300.0, 0.0, 1.0), (300.0, 0.1, math.nan)):
        with pytest.raises(ConfigError):
            notch_tf(fn, zz, zp, DT)
    with pytest.raises(ConfigError):
        PID(DT, PIDGains(notch_fn=1500.0))  # above Nyquist at 2 kHz: refused at construction


def test_the_per_sample_notch_is_the_filter_and_starts_in_steady_state():
    rng = np.random.default_rng(3)
    x = 40.0 + rng.normal(0.0, 5.0, 3000)
    n = Notch(350.0, 0.04, 1.0, DT)
    n.reset(x[0])
    y = np.array([n.step(v) for v in x])
    num, den = notch_tf(350.0, 0.04, 1.0, DT)
    zi = x[0] * (np.cumsum(num[::-1])[::-1][1:] - np.cumsum(den[::-1])[::-1][1:])  # steady state at x[0]
    ref = lfilter(num, den, x, zi=zi)[0]
    assert y == pytest.approx(ref, abs=1e-9)
    n.reset(12.5)
    assert [n.step(12.5) for _ in range(50)] == pytest.approx([12.5] * 50, abs=1e-12)


def test_the_notch_takes_the_mode_out_of_the_pid_command():
    """A command swinging at fn reaches the stage attenuated by ζz/ζp, one at 10 Hz unchanged (within 2 %)."""
    g = PIDGains(kp=1.0e6, ki=0.0, notch_fn=350.0, notch_zeta_zero=0.04, notch_zeta_pole=1.0)
    num, den = controller_tf("pid", g, pea_default(), DT)
    plain = controller_tf("pid", replace(g, notch_fn=0.0), pea_default(), DT)
    assert _gain(num, den, 350.0) / _gain(*plain, 350.0) == pytest.approx(0.04, rel=1e-6)
    assert _gain(num, den, 10.0) / _gain(*plain, 10.0) == pytest.approx(1.0, abs=0.02)


def test_adding_or_removing_a_notch_on_a_running_pid_is_bumpless():
    """The notch swapped in (or out) mid-run starts at the command in force: the next command moves by the
    integrator's own increment, not by what a notch started from rest would hold back (b0·u ≈ 20 V here)."""
    pid = make_controller("pid", pea_default(), DT)
    y, r = 5e-6, 5e-6 + 1e-8          # a constant error: the command ramps by K_i·Δt·e = 0.04 V per sample
    pid.reset(y, 30.0, r)
    us = [pid.step(r, y) for _ in range(100)]
    inc = us[-1] - us[-2]
    assert inc == pytest.approx(PIDGains().ki * DT * 1e-8, rel=1e-6)
    for fn in (350.0, 0.0, 500.0):
        pid.set_gains(replace(pid.gains, notch_fn=fn, notch_zeta_zero=0.04, notch_zeta_pole=1.0))
        us += [pid.step(r, y) for _ in range(3)]
        jumps = np.diff(us[-4:])
        assert np.all(np.abs(jumps) <= 1.5 * inc), (fn, jumps)


@pytest.mark.parametrize(("fn", "zeta"), [(300.0, 0.02), (350.0, 0.04), (500.0, 0.01)])
def test_the_guard_notches_pid_and_keeps_more_gain_robust_over_the_mode_envelope(fn, zeta):
    """On a lightly damped mode the guard runs PID with a notch at it and less derating than without, and the
    notched loop is robust for every stage mode within MODE_TOLERANCE (a notch relies on the mode it was placed
    on); with notch=False it derates as before."""
    m, res = pea_default(), Resonance(fn, zeta)
    with_notch = guard("pid", PIDGains(), m, DT, res)
    without = guard("pid", PIDGains(), m, DT, res, notch=False)
    assert with_notch.gains.notch_fn == fn and without.gains.notch_fn == 0.0
    assert with_notch.gains.kp > 2.0 * without.gains.kp, (with_notch.message, without.message)
    assert "notch" in with_notch.message
    assert check_loop("pid", with_notch.gains, m, DT, res).robust
    mu = _mu_max(m, 0.0, 150.0)  # the check's worst-case incremental gain, as check_loop takes it
    cn, cd = controller_tf("pid", with_notch.gains, m, DT)
    df, kz = MODE_TOLERANCE
    for f in (1 - df, 1.0, 1 + df):
        for z in (1 / kz, 1.0, kz):
            pn, pd = plant_tf(m, DT, Resonance(fn * f, zeta * z), mu)
            for gamma in (0.5, 1.0, 2.0):  # and the gain margin both ways
                assert np.max(np.abs(closed_loop_poles(cn, cd, pn, pd, gamma))) < 1.0, (f, z, gamma)


def _resonant_plant(fn: float, zeta: float, seed: int = 0) -> SimPlant:
    from hyst_sim.plant import Plant, PlantConfig
    from hyst_sim.truth_effects import Dynamics

    cfg = PlantConfig.for_profile("pea", 1.0 / DT, seed=seed)
    return SimPlant(Plant(cfg.replace(effects=cfg.effects.with_effects(dynamics=Dynamics(strength=fn, damping=zeta)))))


@pytest.mark.parametrize("stage_f", [0.9, 1.0, 1.1])
def test_the_notched_pid_tracks_the_resonant_stage_better_than_the_derated_one(stage_f):
    """In the loop (the sim's stage with its hysteresis and a 350 Hz, ζ 0.04 mode; the notch placed on the
    identified 350 Hz while the stage's mode is 0.9-1.1x that): bounded, and a 10 Hz sine tracked at least 2x better
    than with the derating alone."""
    m, res = pea_default(), Resonance(350.0, 0.04)
    runs = {}
    for tag, use in (("notch", True), ("plain", False)):
        g = guard("pid", PIDGains(), m, DT, res, notch=use).gains
        out = run_closed_loop(make_controller("pid", m, DT, gains=g), "sine:10", 2.0,
                              plant=_resonant_plant(350.0 * stage_f, 0.04), skip=0.5)
        assert out.finite
        e = np.abs(out.error)
        half = e.size // 2
        assert e[half:].max() <= 1.5 * e[:half].max() + 20e-9, tag  # bounded, not growing
        runs[tag] = out.rmse
    assert runs["notch"] < 0.5 * runs["plain"], runs


def test_a_configured_notch_is_kept_and_checked_as_configured():
    """A user's own notch is not replaced; the loop is checked with it (here placed far from the mode: the check
    sees that it does not help)."""
    m, res = pea_default(), Resonance(350.0, 0.04)
    g = PIDGains(notch_fn=100.0, notch_zeta_zero=0.05, notch_zeta_pole=0.5)
    v = guard("pid", g, m, DT, res)
    assert v.gains.notch_fn == 100.0
    assert notched(PIDGains(), Resonance(950.0, 0.04), DT) is None  # beyond 0.9 x Nyquist at 2 kHz: no notch
