"""Oscillation watch: a law ringing on a stage mode its model does not know is derated, never left unstable;
nothing a reference asks for trips it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hyst_bringup.loop import default_plant, run_closed_loop
from hyst_control.controllers import make_controller, make_supervised
from hyst_control.supervisor import OscillationMonitor
from hyst_model.core import pea_default

RATE = 2000.0
DT = 1.0 / RATE


def _first_flag(u: np.ndarray, v_range=(0.0, 150.0)) -> float:
    """Seconds until the monitor flags ``u`` (inf: never)."""
    m = OscillationMonitor(DT, v_range)
    for k, v in enumerate(u):
        if m.update(float(v)):
            return k * DT
    return math.inf


def test_monitor_ignores_what_references_and_noise_ask_for():
    t = np.arange(int(2 * RATE)) * DT
    rng = np.random.default_rng(0)
    assert _first_flag(75 + 75 * np.sin(2 * np.pi * 100 * t)) == math.inf          # 100 Hz over the whole range
    assert _first_flag(np.where(np.sin(2 * np.pi * 5 * t) > 0, 150.0, 0.0)) == math.inf  # full-range steps
    assert _first_flag(75 + rng.normal(0, 0.2, t.size)) == math.inf                 # a noisy command
    assert _first_flag(np.clip(75 + 90 * np.sin(2 * np.pi * 100 * t), 0, 150)) == math.inf  # clipped at 100 Hz


@pytest.mark.parametrize("fn", [300.0, 520.0, 900.0])
def test_monitor_flags_a_ringing_command_quickly(fn):
    t = np.arange(int(1 * RATE)) * DT
    small = 75 + 2.0 * np.sin(2 * np.pi * fn * t)                 # a bounded limit cycle of ±2 V
    clipped = np.clip(75 + 200 * np.sin(2 * np.pi * fn * t), 0, 150)  # banging between the limits
    assert _first_flag(small) < 0.1
    assert _first_flag(clipped) < 0.1


@pytest.mark.parametrize("alg", ["dppc", "dmrac", "pid"])
@pytest.mark.parametrize("fn", [320.0, 850.0])
def test_unmodelled_resonance_is_derated_not_left_unstable(alg, fn):
    """The model knows nothing of the stage's mode: the default gains ring (µm, the command between its
    limits); watched, the law is derated and the loop settles; the events say what was done."""
    plant = {"dynamics": fn}
    raw = run_closed_loop(make_controller(alg, pea_default(), DT), "sine:10", 2.0,
                          plant=default_plant(RATE, seed=3, **plant), settle=0.5)
    c = make_supervised(alg, pea_default(), DT)
    sup = run_closed_loop(c, "sine:10", 2.0, plant=default_plant(RATE, seed=3, **plant), settle=0.5)
    assert not raw.finite or raw.rmse > 1e-6, raw.rmse  # the premise: unwatched, the loop is unstable
    assert sup.finite
    late = float(np.sqrt(np.mean((sup.y - sup.r)[-1000:] ** 2)))
    limit = 4e-6 if alg == "pid" else 0.3e-6  # PID derated by 10-100x is slow; the model-based laws track
    assert late < limit, late
    assert c.events and all("oscillates" in e for e in c.events)
    assert c.state()["derated"] >= 1


@pytest.mark.parametrize("alg", ["dppc", "dmrac", "pid", "open_loop"])
@pytest.mark.parametrize("ref", ["sine:30", "step", "c1", "c3", "sine:100:14"])
def test_no_derating_without_an_oscillation(alg, ref):
    c = make_supervised(alg, pea_default(), DT)
    r = run_closed_loop(c, ref, 2.0, plant=default_plant(RATE, seed=3), settle=0.5)
    assert r.finite and c.events == [] and c.level == 0


def test_policy_warn_only_reports():
    c = make_supervised("dppc", pea_default(), DT, act=False)
    r = run_closed_loop(c, "sine:10", 1.0, plant=default_plant(RATE, seed=3, dynamics=520.0), settle=0.5)
    assert c.events and "gains kept" in c.events[0] and c.level == 0
    assert not r.finite or r.rmse > 1e-6


def test_a_command_swinging_on_purpose_with_a_smooth_output_is_not_an_oscillation():
    """A resonance inverted on the reference makes the command swing at the mode's frequency while the output
    stays smooth: with the output watched too (y_span given) that is not flagged; a swinging output is."""
    t = np.arange(int(1 * RATE)) * DT
    u = 75 + 3.0 * np.sin(2 * np.pi * 520 * t)
    smooth = 15e-6 + 5e-6 * np.sin(2 * np.pi * 10 * t) + np.random.default_rng(1).normal(0, 2e-9, t.size)
    ringing = smooth + 0.3e-6 * np.sin(2 * np.pi * 520 * t)

    def flags(y):
        m = OscillationMonitor(DT, (0.0, 150.0), y_span=30e-6)
        return any(m.update(float(a), float(b)) for a, b in zip(u, y))

    assert not flags(smooth)
    assert flags(ringing)


def test_no_fallback_to_the_open_loop_inverse_on_a_model_that_runs_away_open_loop():
    """At the last derating level the watch falls back to the open-loop inverse — unless the model runs away
    within the command limits (hyst_control.controller_settings.model_divergence): then the law is kept and the
    event says why. With the profile's model the fallback still happens."""
    from hyst_control.supervisor import LEVELS

    for model, falls in ((pea_default(), True), (pea_default().replace(alpha1=1.0), False)):
        c = make_supervised("dppc", model, DT)
        c.reset(15e-6, 75.0, 15e-6)
        c.level = len(LEVELS["dppc"])  # every derating step used up
        c._escalate(15e-6, 15e-6)
        assert (c.algorithm == "open_loop") is falls, c.events
        if not falls:
            assert "no fallback" in c.events[-1] and "diverges" in c.events[-1]
