"""The driver's own emulator plant: a linear stage behind the profile's amplifier (no simulator needed)."""
from __future__ import annotations

import math
import subprocess
import sys

import pytest

from hyst_common.profiles import GMA, PEA
from hyst_driver.errors import ConfigError
from hyst_driver.linear_stage import LinearStage, linear_device


def test_amplifier_range_and_slew_hold_and_the_stroke_is_linear():
    s = LinearStage(PEA, 1000.0, noise=0.0)
    step = PEA.slew_max / 1000.0  # 100 V per sample at 1 kHz
    r = s.step(150.0)
    assert r.u_applied == pytest.approx(step) and r.clipped  # slew-limited from 0 V
    for _ in range(3):
        r = s.step(1e9)
    assert r.u_applied == PEA.v_max and r.y == pytest.approx(PEA.stroke, abs=PEA.sensor_resolution)
    r = s.step(math.nan)  # NaN holds the last value
    assert r.u_applied == PEA.v_max and r.clipped
    r = s.step(75.0)
    assert r.u_applied == 75.0 and not r.clipped and r.y == pytest.approx(PEA.stroke / 2, abs=2e-9)
    assert round(r.y / PEA.sensor_resolution) * PEA.sensor_resolution == pytest.approx(r.y)


def test_gma_is_bipolar_and_rests_at_zero_volts():
    s = LinearStage(GMA, 1000.0, noise=0.0)
    assert s.u_applied == 0.0 and s.config.v_min == -5.0
    assert s.step(-5.0).y == pytest.approx(0.0, abs=2e-9)


def test_noise_is_seeded():
    def run(**kw):
        s = LinearStage(PEA, 1000.0, **kw)
        return [s.step(50.0).y for _ in range(50)]
    a, b = run(seed=3), run(seed=3)
    assert a == b                                       # the same seed, the same readings
    assert run(seed=4) != a                             # another seed, other readings
    assert run(seed=3, noise=0.0) != a                  # and they are noisy
    assert len(set(a)) > 1


def test_a_hysteretic_stage_is_refused_with_the_way_to_get_one():
    with pytest.raises(ConfigError, match="hyst_emulator"):
        linear_device("pea", 1000.0, scenario="hidden_creep.yaml")
    run = [sys.executable, "-c", "import sys; from hyst_driver.emulator import main; sys.exit(main())",
           "--scenario", "x.yaml"]
    r = subprocess.run(run, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "hyst_emulator" in r.stderr
