"""Voltage safety: property test over random command streams (NaN, inf, huge) down to the encoded bytes."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hyst_driver import protocol_ascii as hdb
from hyst_driver import protocol_gcs as gcs
from hyst_driver.adapter import AsciiAdapter, GcsAdapter
from hyst_driver.errors import ConfigError
from hyst_driver.safety import CommandWatchdog, Limits, VoltageLimiter

PROFILES = {"pea": (0.0, 150.0), "gma": (-5.0, 5.0)}


@st.composite
def limits(draw):
    lo, hi = PROFILES[draw(st.sampled_from(sorted(PROFILES)))]
    a = draw(st.floats(lo, hi, allow_nan=False))
    b = draw(st.floats(lo, hi, allow_nan=False))
    v_min, v_max = min(a, b), max(a, b)
    if v_max - v_min < 1e-3:
        v_max = min(hi, v_min + 1e-3) if v_min + 1e-3 <= hi else v_max
        v_min = v_max - 1e-3
    v_safe = draw(st.floats(v_min, v_max, allow_nan=False))
    slew = draw(st.floats(1.0, 1e6, allow_nan=False))
    safe_rate = draw(st.one_of(st.just(math.inf), st.floats(1e-3, 1e7)))
    return Limits(v_min, v_max, slew, v_safe, dt_max=1e-3, safe_ramp_rate=safe_rate)


requests = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),                      # anything, incl. 1e308, -0.0, subnormals
    st.floats(-200.0, 200.0),                                            # around the windows
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 150.0000001, -5.0000001, 0.0]),
)
dts = st.one_of(st.floats(0.0, 0.01), st.sampled_from([0.0, -1.0, math.nan, math.inf, 1e9]))


def _decoded_volts(adapter, v: float) -> float:
    data = adapter.set_voltage(v)
    if isinstance(adapter, AsciiAdapter):
        return hdb.decode_command(data).uv / hdb.UV_PER_V
    return gcs.decode_command(data).volts


@settings(max_examples=300, deadline=None)
@given(lim=limits(), v0=requests, stream=st.lists(st.tuples(requests, dts, st.booleans()), min_size=1, max_size=60),
       new_lim=st.one_of(st.none(), limits()))
def test_no_out_of_limit_voltage_is_ever_encoded(lim, v0, stream, new_lim):
    adapters = (AsciiAdapter(), GcsAdapter())
    lim_now = lim
    limiter = VoltageLimiter(lim, v0)
    prev = limiter.value
    for i, (req, dt, watchdog) in enumerate(stream):
        swapped = False
        if new_lim is not None and i == len(stream) // 2:
            limiter.set_limits(new_lim)
            lim_now, swapped = new_lim, True
        if watchdog:  # the command stream stopped: ramp to v_safe
            limiter.request_safe()
            out = limiter.step(dt)
        else:
            out = limiter.update(req, dt)
        assert lim_now.v_min <= out <= lim_now.v_max
        for ad in adapters:
            wire = _decoded_volts(ad, out)
            assert lim_now.v_min <= wire <= lim_now.v_max, (ad.name, out, wire)
        if not swapped:
            step_max = lim_now.slew_max * (min(dt, lim_now.dt_max) if math.isfinite(dt) and dt > 0 else 0.0)
            assert abs(out - prev) <= step_max + 1e-9
        prev = out


def test_limiter_tracks_clips_and_rejects():
    lim = Limits(0.0, 150.0, slew_max=1e5, v_safe=0.0, dt_max=1e-3)   # 100 V per 1 ms sample
    lz = VoltageLimiter(lim)
    assert lz.value == 0.0
    assert lz.update(50.0, 1e-3) == 50.0                                # within one slew step
    assert lz.update(160.0, 1e-3) == 150.0 and lz.counts.clipped == 1   # saturation clips
    assert lz.update(math.nan, 1e-3) == 150.0                           # rejected: target kept
    assert lz.update(1e6, 1e-3) == 150.0                                # huge: rejected, not clipped to v_max
    assert lz.counts.rejected == 2 and lz.target == 150.0
    assert lz.update(-20.0, 1e-3) == 50.0                               # clipped to 0, slew-limited on the way
    assert lz.step(1e-3) == 0.0 and lz.settled
    assert lz.update(-151.0, 1e-3) == 0.0 and lz.counts.rejected == 3   # > one span below: rejected


def test_long_pause_does_not_license_a_step():
    lz = VoltageLimiter(Limits(0.0, 150.0, slew_max=1000.0, v_safe=0.0, dt_max=1e-3))
    assert lz.update(150.0, 10.0) == pytest.approx(1.0)   # 1000 V/s for one 1 ms sample, not 10 s
    n = 1
    while not lz.settled:
        lz.step(1e-3)
        n += 1
    assert n == 150 and lz.value == 150.0


def test_ramp_to_safe_and_limit_swap():
    lz = VoltageLimiter(Limits(-5.0, 5.0, slew_max=100.0, v_safe=0.0), v0=4.0)
    lz.request_safe()
    out = [lz.step(1e-3) for _ in range(50)]
    assert out[0] == 3.9 and out[-1] == 0.0 and lz.settled
    assert all(b <= a for a, b in zip(out, out[1:]))
    lz.reset(4.5)
    lz.set_limits(Limits(-1.0, 1.0, slew_max=100.0, v_safe=0.0))
    assert lz.value == 1.0  # brought inside the new window at once
    lz.reset(math.nan)
    assert lz.value == 0.0


def test_safe_ramp_rate_applies_to_ramps_to_safe_only():
    lz = VoltageLimiter(Limits(0.0, 150.0, slew_max=1e5, v_safe=0.0, safe_ramp_rate=100.0), v0=150.0)
    lz.request_safe()
    assert lz.step(1e-3) == 149.9                      # 100 V/s, not 100 V per sample
    assert lz.update(20.0, 1e-3) == 49.9               # a real command moves at slew_max (100 V per sample)
    with pytest.raises(ConfigError):
        Limits(0.0, 1.0, 1.0, 0.0, safe_ramp_rate=0.0)


def test_output_is_on_the_wire_grid_at_awkward_limits():
    lim = Limits(0.1234567, 0.3456789, slew_max=1e9, v_safe=0.2)
    lz = VoltageLimiter(lim)
    assert lz.update(0.5, 1e-3) == 0.345678 and lz.update(0.0, 1e-3) == 0.123457
    assert lz.update(1.0, 1e-3) == 0.123457 and lz.counts.rejected == 1  # > one span above: huge
    assert hdb.decode_command(AsciiAdapter().set_voltage(lz.value)).uv == 123457


@pytest.mark.parametrize("kw", [
    dict(v_min=1.0, v_max=1.0, slew_max=1.0, v_safe=1.0), dict(v_min=0.0, v_max=1.0, slew_max=0.0, v_safe=0.5),
    dict(v_min=0.0, v_max=1.0, slew_max=1.0, v_safe=2.0), dict(v_min=math.nan, v_max=1.0, slew_max=1.0, v_safe=0.5),
    dict(v_min=0.0, v_max=math.inf, slew_max=1.0, v_safe=0.5),
])
def test_bad_limits_are_refused(kw):
    with pytest.raises(ConfigError):
        Limits(**kw)


def test_watchdog():
    wd = CommandWatchdog(0.1)
    assert wd.expired(0.0)
    wd.feed(1.0)
    assert not wd.expired(1.05) and wd.expired(1.2)
