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


def _run(lk: DeviceLink, seconds: float, volts: float | None = None) -> list:
    out = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        lk.wait(lk.next_deadline() - time.monotonic())
        out += lk.service()
        if volts is not None:
            lk.command(volts)
    return out


def test_handshake_and_sample_rate(link):
    _run(link, 1.0)
    h = link.snapshot()
    assert h.state == "running" and h.identity, h
    got = _run(link, 1.0)
    assert len(got) >= 0.9 * RATE if link.adapter.streaming else len(got) >= 100, len(got)
    assert sum(h.bad_frames.values()) == 0 and link.snapshot().lost_samples == h.lost_samples


def test_small_step_reads_back_and_ramps_to_safe(link):
    _run(link, 0.5)
    assert link.health.state == "running"
    v = link.limiter.limits.v_safe + float(os.environ.get("HYST_DEVICE_STEP", "2.0"))
    got = _run(link, 0.5, volts=v)
    assert abs(got[-1][1].applied_v - v) < 0.01, got[-1]
    assert link.ramp_to_safe(5.0)


def test_reconnects_after_the_port_is_closed(link):
    _run(link, 0.5)
    c0 = link.health.connects
    link.transport.close()
    _run(link, 1.0)
    assert link.health.connects == c0 + 1 and link.health.state == "running"
