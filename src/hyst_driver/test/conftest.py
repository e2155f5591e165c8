"""Fixtures of the hyst_driver tests: an emulated stage on a pty and a DeviceLink talking to it."""
from __future__ import annotations

import math
import random
import time

import pytest

from hyst_driver.adapter import make_adapter
from hyst_driver.emulator import PtyEmulator
from hyst_driver.safety import Limits
from hyst_driver.transport import DeviceLink, SerialTransport
from hyst_driver.linear_stage import linear_device

#: Driver limits deliberately narrower than the emulated amplifier (0..150 V), so that the device would accept
#: a voltage the driver must never send.
TEST_LIMITS = Limits(v_min=10.0, v_max=120.0, slew_max=2.0e4, v_safe=20.0, dt_max=1e-3)


def hostile_commands(seed: int):
    """Endless command stream: mostly out-of-window values, with NaN, ±inf and huge values mixed in."""
    rng = random.Random(seed)
    specials = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e6, 150.0, 0.0, -5.0]
    while True:
        yield rng.choice(specials) if rng.random() < 0.1 else rng.uniform(-50.0, 300.0)


class Rig:
    """An emulator thread plus a DeviceLink serviced from the test's own thread."""

    def __init__(self, protocol: str, limits: Limits = TEST_LIMITS, seed: int = 0, **link_kw) -> None:
        self.device = linear_device("pea", 1000.0, seed=seed)
        self.emu = PtyEmulator(self.device, seed=seed).start()
        ad = make_adapter(protocol, 2e-9, (-15.0, 165.0))
        kw = dict(command_timeout=0.05, link_timeout=0.1, err_poll_period=0.01)
        kw.update(link_kw)
        self.link = DeviceLink(SerialTransport(self.emu.link, backoff=(0.005, 0.05)), ad, limits, 1000, **kw)
        self.commands = hostile_commands(seed)
        self.readings = 0
        self.last_seq: int | None = None  # device sample number of the newest reading (HDB/1)

    def run(self, seconds: float, command: bool = True) -> int:
        """Service the link for ``seconds``, answering every reading with the next hostile command."""
        n = 0
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            self.link.wait(min(self.link.next_deadline(), t_end) - time.monotonic())
            for _, r in self.link.service():
                n += 1
                if r.seq is not None:
                    self.last_seq = r.seq
                if command:
                    self.link.command(next(self.commands))
        self.readings += n
        return n

    def run_until(self, pred, timeout: float, command: bool = True) -> bool:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            self.run(0.005, command)
            if pred():
                return True
        return False

    def fault_read(self, n_injected: int, timeout: float = 10.0) -> bool:
        """Service the link until the host has read past the ``n_injected``-th fault the emulator put on the
        wire (all kinds counted): an event, not a time. HDB/1: a sample numbered two after the fault (FIFO).
        GCS (polled, one exchange in flight): two more samples once the fault is out, the second answering a
        poll sent after it."""
        if not self.run_until(lambda: sum(self.emu.injected.values()) >= n_injected, timeout):
            return False
        if self.link.adapter.streaming:
            mark = self.emu.fault_seq
            return self.run_until(lambda: self.last_seq is not None
                                  and 2 <= (self.last_seq - mark) % 0x10000 < 0x8000, timeout)
        goal = self.link.health.samples + 2
        return self.run_until(lambda: self.link.health.samples >= goal, timeout)

    def close(self) -> None:
        self.link.close()
        self.emu.stop()


@pytest.fixture
def make_rig():
    rigs = []

    def factory(protocol: str, **kw) -> Rig:
        rig = Rig(protocol, **kw)
        rigs.append(rig)
        return rig

    yield factory
    for r in rigs:
        r.close()


def assert_received_within(received, limits: Limits) -> None:
    """Every voltage the device ever received is inside the window and slew-consistent with the previous."""
    assert received, "the device received no voltage at all"
    lo, hi = min(received), max(received)
    assert limits.v_min <= lo and hi <= limits.v_max, (lo, hi)
    step = limits.slew_max * limits.dt_max + 1e-6
    worst = max((abs(b - a) for a, b in zip(received, received[1:])), default=0.0)
    assert worst <= step, f"consecutive voltages differ by {worst} V > {step} V"


def assert_applied_within(device, limits: Limits, start: int = 0) -> None:
    """The voltage the emulated amplifier applied, sample by sample from ``start``: no step larger than one
    sample of slew (two setpoints delivered within one sample count as the one step the stage feels), and inside
    the window from the first sample the driver's first write moved it (it starts at the profile's 0 V)."""
    a = device.applied[start:]
    assert len(a) > 1, "the device took no samples"
    step = limits.slew_max * limits.dt_max + 1e-6
    worst, at = max((abs(a[k] - a[k - 1]), k) for k in range(1, len(a)))
    assert worst <= step, (f"the applied voltage stepped {worst} V in one device sample > {step} V: sample "
                           f"{start + at} of {start + len(a)}, {list(a[max(0, at - 4):at + 3])}; first received "
                           f"{device.received[:4]}")
    moved = next((k for k in range(len(a)) if a[k] != a[0]), len(a))
    if moved < len(a):
        lo, hi = min(a[moved:]), max(a[moved:])
        assert limits.v_min <= lo and hi <= limits.v_max, (lo, hi)


@pytest.fixture
def check_applied():
    """The invariant checker :func:`assert_applied_within`."""
    return assert_applied_within


@pytest.fixture
def check_received():
    """The invariant checker :func:`assert_received_within` (fixtures avoid importing conftest)."""
    return assert_received_within


@pytest.fixture
def test_limits() -> Limits:
    return TEST_LIMITS
