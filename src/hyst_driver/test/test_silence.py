"""A device silence is reported as a timeout whether or not the host was awake to watch it.

Deterministic: a scripted port and a hand-driven clock, so the host 'stalls' exactly when the test says. Seen in
CI (fault test, run 50 of 100): the emulator went silent for 40 ms while the test's thread was descheduled; the
samples after the silence then arrived together, the arrival clock never saw a gap, and the silence went
unreported. The device's own sample clock shows it.
"""
from __future__ import annotations

from hyst_driver import protocol_ascii as hdb
from hyst_driver.adapter import make_adapter
from hyst_driver.safety import Limits
from hyst_driver.transport import DeviceLink, SerialTransport

LIMITS = Limits(v_min=0.0, v_max=150.0, slew_max=1e5, v_safe=0.0, dt_max=0.001, quantum=1e-6,
                safe_ramp_rate=float("inf"), flight_max=1.0)


class ScriptedPort:
    """pyserial-like port: the test queues the device's bytes; every written byte is kept."""

    def __init__(self) -> None:
        self.inbox = bytearray()
        self.written = bytearray()

    def read(self, n: int) -> bytes:
        out, self.inbox = bytes(self.inbox[:n]), self.inbox[n:]
        return out

    def write(self, data: bytes) -> int:
        self.written += data
        return len(data)

    def reset_input_buffer(self) -> None:
        pass

    def close(self) -> None:
        pass

    def fileno(self) -> int:
        raise NotImplementedError


class Rig:
    def __init__(self) -> None:
        self.port = ScriptedPort()
        self.now = 100.0
        transport = SerialTransport("scripted://", opener=lambda *a, **k: self.port)
        self.link = DeviceLink(transport, make_adapter("ascii", 2e-9, (-15.0, 165.0)), LIMITS, 1000,
                               link_timeout=0.5, clock=lambda: self.now)
        self.seq, self.t_us = 0, 5_000_000

    def sample(self, n: int = 1, skip_s: float = 0.0) -> None:
        """Queue ``n`` device samples at 1 kHz, the first one ``skip_s`` after the last (a silence)."""
        self.t_us += round(skip_s * 1e6)
        self.seq += round(skip_s * 1e3)
        for _ in range(n):
            self.seq, self.t_us = (self.seq + 1) % 0x10000, self.t_us + 1000
            self.port.inbox += hdb.encode_sample(hdb.Sample(self.seq, self.t_us, 1000, hdb.volts_to_uv(10.0)))

    def step(self, dt: float = 0.001) -> None:
        self.now += dt
        self.link.service()

    def start(self) -> None:
        self.link.service()  # opens, sends the handshake
        self.port.inbox += hdb.encode_identity(hdb.Identity("EMU", "HDB", "1", "1.0"))
        for _ in range(10):
            self.sample()
            self.step()
        assert self.link.health.state == "running", self.link.snapshot()


def test_a_silence_the_host_watched_is_one_timeout():
    rig = Rig()
    rig.start()
    for _ in range(50):  # 50 ms of silence, serviced every ms
        rig.step()
    rig.sample(5, skip_s=0.05)
    rig.step()
    assert rig.link.health.timeouts == 1  # seen live; the gap in the device clock is the same silence


def test_a_silence_the_host_slept_through_is_still_a_timeout():
    rig = Rig()
    rig.start()
    # the host is descheduled for 60 ms; meanwhile the device is silent for 40 ms and then streams again
    rig.sample(20, skip_s=0.04)
    rig.step(0.06)
    h = rig.link.health
    assert h.state == "running" and h.timeouts == 1, rig.link.snapshot()
    assert h.lost_samples == 40


def test_a_host_stall_without_a_device_silence_is_no_timeout():
    rig = Rig()
    rig.start()
    rig.sample(60)  # every sample buffered while the host slept 60 ms
    rig.step(0.06)
    assert rig.link.health.timeouts == 0 and rig.link.health.lost_samples == 0
