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
    limiter = VoltageLimiter(lim, v0, track_flight=False)  # invariants 1-3; invariant 4 is tested below
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
    lz = VoltageLimiter(lim, track_flight=False)  # every output counts as applied at once
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
    lz = VoltageLimiter(Limits(0.0, 150.0, slew_max=1000.0, v_safe=0.0, dt_max=1e-3), track_flight=False)
    assert lz.update(150.0, 10.0) == pytest.approx(1.0)   # 1000 V/s for one 1 ms sample, not 10 s
    n = 1
    while not lz.settled:
        lz.step(1e-3)
        n += 1
    assert n == 150 and lz.value == 150.0


def test_ramp_to_safe_and_limit_swap():
    lz = VoltageLimiter(Limits(-5.0, 5.0, slew_max=100.0, v_safe=0.0), v0=4.0, track_flight=False)
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
    lz = VoltageLimiter(Limits(0.0, 150.0, slew_max=1e5, v_safe=0.0, safe_ramp_rate=100.0), v0=150.0,
                        track_flight=False)
    lz.request_safe()
    assert lz.step(1e-3) == 149.9                      # 100 V/s, not 100 V per sample
    assert lz.update(20.0, 1e-3) == 49.9               # a real command moves at slew_max (100 V per sample)
    with pytest.raises(ConfigError):
        Limits(0.0, 1.0, 1.0, 0.0, safe_ramp_rate=0.0)


def test_output_is_on_the_wire_grid_at_awkward_limits():
    lim = Limits(0.1234567, 0.3456789, slew_max=1e9, v_safe=0.2)
    lz = VoltageLimiter(lim, track_flight=False)
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


# ---------------------------------------------------------------- the device's side: what the amplifier applies
#: One event of an interleaving: the host writes (a command, or a watchdog ramp step), the device takes a sample
#: (consuming ``extra`` more setpoints from its input queue than it must), or a read-back reaches the host.
events = st.lists(st.one_of(
    st.tuples(st.just("write"), requests, st.booleans(), st.floats(0.0, 2e-3)),
    # bang-bang inside the window (a fraction of it): the requests that keep the slew limit at work
    st.tuples(st.just("push"), st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0.0, 1.0)), st.floats(0.0, 2e-3)),
    st.tuples(st.just("sample"), st.integers(0, 4), st.floats(0.0, 2e-3)),
    st.tuples(st.just("sample"), st.just(99), st.floats(0.0, 2e-3)),  # everything on the wire at once
    st.tuples(st.just("readback"), st.floats(0.0, 2e-3)),
), min_size=1, max_size=120)


def _device_run(lim: Limits, v0: float, evs) -> tuple[list[float], VoltageLimiter]:
    """Drive a limiter against a model device over a FIFO link; return the voltage applied at every sample.

    The device applies, at each of its samples, the last setpoint it has received; setpoints take any time to
    arrive (any number may arrive within one sample), but no longer than ``flight_max`` (the limiter's one
    assumption). Read-backs of its samples reach the host in order, any time later.
    """
    limiter = VoltageLimiter(lim, v0)
    applied = [limiter.value]             # the amplifier starts where the limiter was seeded
    link: list[tuple[float, float]] = []  # setpoints on the wire: (V, time written)
    readbacks: list[tuple[float, float]] = []
    t = t_write = 0.0
    for ev in evs:
        t += ev[-1]
        if ev[0] in ("write", "push"):
            req, watchdog = (ev[1], ev[2]) if ev[0] == "write" else (lim.v_min + ev[1] * (lim.v_max - lim.v_min), False)
            if watchdog:
                limiter.request_safe()
            else:
                limiter.request(req)
            v = limiter.step(t - t_write)
            if not limiter.hold:
                limiter.sent(t)
                link.append((v, t))
                t_write = t
        elif ev[0] == "sample":
            n = sum(1 for _, tw in link if tw <= t - lim.flight_max) + ev[1]  # those must have arrived
            taken, link[:] = link[:n], link[n:]
            if taken:
                applied.append(taken[-1][0])
            else:
                applied.append(applied[-1])
            readbacks.append((applied[-1], t))
        elif readbacks:
            limiter.observe(*readbacks.pop(0))
    return applied, limiter


@settings(max_examples=400, deadline=None)
@given(lim=limits(), frac=st.floats(0.0, 1.0), evs=events, flight=st.sampled_from([2e-3, 5e-3, 0.1]),
       slew=st.one_of(st.none(), st.floats(100.0, 5e4)))
def test_applied_voltage_never_steps_more_than_one_sample_of_slew(lim, frac, evs, flight, slew):
    """Any interleaving of writes, device samples and read-backs: the voltage the device applies changes by at
    most ``slew_max · dt_max`` per device sample and stays in the window. (``slew``: a slew limit small against
    the profiles' windows, so that the limit is reached often, not only in corner cases.)"""
    from dataclasses import replace

    lim = replace(lim, flight_max=flight, slew_max=lim.slew_max if slew is None else slew)
    applied, _ = _device_run(lim, lim.v_min + frac * (lim.v_max - lim.v_min), evs)
    step = lim.slew_max * lim.dt_max + 1e-9
    for a, b in zip(applied, applied[1:]):
        assert abs(b - a) <= step, (a, b, step)
        assert lim.v_min <= b <= lim.v_max


def test_two_writes_within_one_device_sample_cannot_make_a_double_step():
    """The failure measured under load: +20 V written, +20 V again before the device sampled the first."""
    lim = Limits(0.0, 150.0, slew_max=2e4, v_safe=0.0, dt_max=1e-3)  # 20 V per device sample
    lz = VoltageLimiter(lim, 0.0)
    assert lz.update(100.0, 1e-3) == 20.0
    lz.sent(0.001)
    assert lz.update(100.0, 1e-3) == 20.0 and not lz.hold  # 0 V may still be applied: 40 V would be 2 samples
    lz.sent(0.002)
    assert lz.in_flight == (20.0,) and lz.confirmed == 0.0
    lz.observe(0.0, 0.002)                                 # the device has not applied it yet: no progress
    assert lz.update(100.0, 1e-3) == 20.0
    lz.observe(20.0, 0.003)                                # now it has: the next write may move on
    assert lz.in_flight == () and lz.confirmed == 20.0
    assert lz.update(100.0, 1e-3) == 40.0


def test_hold_when_nothing_is_admissible_and_resume_on_readback():
    lim = Limits(0.0, 150.0, slew_max=2e4, v_safe=0.0, dt_max=1e-3)
    lz = VoltageLimiter(lim, 50.0)
    lz.request(0.0)
    for t, v in ((1, 30.0), (2, 30.0)):
        assert lz.step(1e-3) == v
        lz.sent(t * 1e-3)
    lz.observe(30.0, 0.003)
    lz.request(150.0)
    for t, v in ((4, 50.0), (5, 50.0)):
        assert lz.step(1e-3) == v
        lz.sent(t * 1e-3)
    lz.set_limits(Limits(0.0, 150.0, slew_max=9e3, v_safe=0.0, dt_max=1e-3))  # 9 V per sample now
    assert lz.step(1e-3) == 50.0 and lz.hold   # 30 V confirmed, 50 V in flight: nothing is within 9 V of both
    assert lz.counts.held == 1
    lz.observe(50.0, 0.006)
    assert lz.step(1e-3) == 59.0 and not lz.hold


def test_a_lost_write_is_forgotten_after_two_later_samples_and_a_device_reset_is_followed():
    lim = Limits(0.0, 150.0, slew_max=2e4, v_safe=0.0, dt_max=1e-3, flight_max=0.01)
    lz = VoltageLimiter(lim, 50.0)
    assert lz.update(70.0, 1e-3) == 70.0
    lz.sent(0.0)                                           # lost on the wire: the device stays at 50 V
    lz.observe(50.0, 0.005)
    lz.observe(50.0, 0.011)                                # one sample after flight_max: could still be late
    assert lz.in_flight == (70.0,)
    lz.observe(50.0, 0.012)                                # two: it can no longer arrive
    assert lz.in_flight == () and lz.counts.expired == 1
    lz.observe(0.0, 0.013)                                 # once: a corrupted line is not believed
    assert lz.confirmed == 50.0 and lz.counts.unexplained == 1
    assert lz.step(1e-3) == 70.0 and lz.hold               # nothing is written until it is settled
    lz.observe(50.0, 0.0135)                               # nor twice with a good one between
    lz.observe(0.0, 0.0137)
    assert lz.confirmed == 50.0 and lz.counts.unexplained == 2
    lz.observe(0.0, 0.014)                                 # twice: the amplifier reset itself to 0 V
    assert lz.confirmed == 0.0 and lz.value == 0.0
    assert lz.update(70.0, 1e-3) == 20.0                   # climbs from there at the slew limit


def test_seeded_outside_the_window_the_first_steps_are_judged_from_the_reported_voltage():
    """A device at 0 V under v_min = 10 V (seen at load: a 29 V first step when the seed was clamped to 9 V)."""
    lz = VoltageLimiter(Limits(10.0, 120.0, slew_max=2e4, v_safe=20.0, dt_max=1e-3))
    lz.reset(0.0)
    assert lz.confirmed == 0.0
    out = []
    for t in range(1, 5):  # none of them confirmed: all may reach the device within one of its samples
        out.append(lz.update(110.0, 1e-3))
        lz.sent(t * 1e-3)
    assert out[0] == 10.0 and max(out) <= 20.0  # into the window at once, then within 20 V of the 0 V applied


def test_apply_delay_is_measured_by_the_read_back_and_only_when_the_sample_time_is_known():
    """Write -> applied, judged by the device's own read-back: what a link that delays commands costs."""
    lim = Limits(0.0, 150.0, slew_max=2e4, v_safe=0.0, dt_max=1e-3)
    lz = VoltageLimiter(lim, 0.0)
    lz.update(100.0, 1e-3)
    lz.sent(0.010)                      # 20 V written
    lz.observe(0.0, 0.0105)             # not applied yet: no delay recorded
    assert list(lz.apply_delays) == []
    lz.observe(20.0, 0.0132)            # applied at the sample taken 3.2 ms after the write
    assert list(lz.apply_delays) == [pytest.approx(0.0032)]
    lz.update(100.0, 1e-3)
    lz.sent(0.020)
    lz.observe(40.0, -math.inf)         # sample time unknown (a polled reply before the clock settled)
    assert len(lz.apply_delays) == 1 and lz.confirmed == 40.0


def test_a_ramp_to_safe_starts_with_one_periods_step_not_the_keepalives_credit():
    """The first step of a watchdog ramp was credited the 0.1 s since the keepalive write: 100 V → 90 V at
    100 V/s, then 0.1-0.3 V per sample."""
    lim = Limits(0.0, 150.0, slew_max=1e5, v_safe=0.0, safe_ramp_rate=100.0, dt_max=1e-3)
    lz = VoltageLimiter(lim, v0=100.0, track_flight=False)
    lz.request_safe()
    assert lz.step(0.1) == pytest.approx(99.9)          # one period at 100 V/s, though 0.1 s went by
    assert lz.step(0.1) == pytest.approx(89.9)          # once ramping, a late write catches up (as before)
    lz.request_safe()                                    # asked again while ramping: no new start
    assert lz.step(0.05) == pytest.approx(84.9)
