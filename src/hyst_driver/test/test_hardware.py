"""Hardware tests: run only with a real device, ``pytest src/hyst_driver/test/test_hardware.py --device PORT``.

Environment: ``HYST_DEVICE_PROTOCOL`` (ascii | gcs, default ascii), ``HYST_DEVICE_PROFILE`` (pea | gma, default
pea), ``HYST_DEVICE_STEP`` (V above v_safe for the step test, default 2 V). The stage moves by that small step
only, at 100 V/s, and is ramped back to v_safe at the end of every test.
"""
from __future__ import annotations

import os
import time

import pytest

from hyst_driver.adapter import make_adapter
from hyst_driver.safety import Limits
from hyst_driver.transport import DeviceLink, SerialTransport

pytestmark = pytest.mark.hardware
RATE = 1000


@pytest.fixture
def link(request):
    port = request.config.getoption("--device")
    if not port:
        pytest.skip("hardware test: give --device PORT")
    from hyst_common.profiles import get_profile

    prof = get_profile(os.environ.get("HYST_DEVICE_PROFILE", "pea"))
    span = prof.v_max - prof.v_min
    ad = make_adapter(os.environ.get("HYST_DEVICE_PROTOCOL", "ascii"), prof.sensor_resolution,
                      (prof.v_min - 0.1 * span, prof.v_max + 0.1 * span))
    lim = Limits(prof.v_min, prof.v_max, 100.0, prof.v_safe, dt_max=1.0 / RATE)
    lk = DeviceLink(SerialTransport(port), ad, lim, RATE, command_timeout=1.0, link_timeout=0.5)
    yield lk
    lk.ramp_to_safe(5.0)
    lk.close()


def _run_until(lk: DeviceLink, done, timeout: float = 10.0, volts: float | None = None) -> list:
    """Service the link until ``done(samples so far)`` holds (or ``timeout`` s pass); the samples."""
    out: list = []
    t_end = time.monotonic() + timeout
    while not done(out) and time.monotonic() < t_end:
        lk.wait(lk.next_deadline() - time.monotonic())
        out += lk.service()
        if volts is not None:
            lk.command(volts)
    return out


def _running(lk: DeviceLink):
    return lambda _out: lk.health.state == "running"


def test_handshake_and_sample_rate(link):
    _run_until(link, _running(link))
    h = link.snapshot()
    assert h.state == "running" and h.identity, h
    got = _run_until(link, lambda out: len(out) >= RATE)
    assert len(got) >= RATE, len(got)
    # the rate is judged on the device's own clock and sequence numbers, not on this machine's wall clock
    rd = [r for _, r in got]
    if link.adapter.streaming and rd[0].device_time is not None:
        span = rd[-1].device_time - rd[0].device_time
        if span > 0:  # (the device clock wraps; a wrap inside the window skips the check)
            assert span == pytest.approx((len(rd) - 1) / RATE, rel=0.01), span
    if rd[0].seq is not None:
        steps = {(b.seq - a.seq) for a, b in zip(rd, rd[1:])}
        assert steps <= {1} or len(steps - {1}) == 1 and all(s < 0 for s in steps - {1}), steps  # 1s, a wrap
    assert sum(h.bad_frames.values()) == 0 and link.snapshot().lost_samples == h.lost_samples


def test_small_step_reads_back_and_ramps_to_safe(link):
    _run_until(link, _running(link))
    assert link.health.state == "running"
    v = link.limiter.limits.v_safe + float(os.environ.get("HYST_DEVICE_STEP", "2.0"))
    got = _run_until(link, lambda out: bool(out) and abs(out[-1][1].applied_v - v) < 0.01, volts=v)
    assert got and abs(got[-1][1].applied_v - v) < 0.01, got[-1:]
    assert link.ramp_to_safe(5.0)


def test_reconnects_after_the_port_is_closed(link):
    _run_until(link, _running(link))
    c0 = link.health.connects
    link.transport.close()
    _run_until(link, lambda _out: link.health.connects == c0 + 1 and link.health.state == "running")
    assert link.health.connects == c0 + 1 and link.health.state == "running"
