"""The device link, :class:`DeviceLink`: one adapter + one transport + the voltage limiter (the serial transport
with reconnect and the device clock are in :mod:`.serial_transport`, re-exported here).

The transport is injected (``opener``, default :func:`serial.serial_for_url`), so tests use ``loop://`` or a pty
pair and the rig uses ``/dev/ttyACM0`` or a stable ``/dev/serial/by-id/...`` path. Nothing here imports rclpy:
the node (``driver_node.py``) runs :meth:`DeviceLink.service` in an I/O thread and publishes the readings.

Link states: ``disconnected`` → (port opens) → ``handshake`` (stop any old stream, identify, read one sample to
learn the voltage the amplifier applies *now* and seed the limiter with it) → ``running``. Any I/O error, a
vanished port, or no sample for ``link_timeout`` closes the port and goes back to ``disconnected``; reopening is
retried with exponential backoff. Voltages only leave through :class:`hyst_driver.safety.VoltageLimiter`.
"""
from __future__ import annotations

import math
import os
import select
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Callable


from .adapter import Adapter, BadFrame, DeviceFault, Identified, Reading
from .errors import EncodeError, LinkError
from .safety import CommandWatchdog, Limits, VoltageLimiter
from .serial_transport import DeviceClock, SerialTransport

__all__ = ["SerialTransport", "DeviceLink", "LinkHealth", "DeviceClock"]


@dataclass
class LinkHealth:
    """Counters and state for ``/diagnostics`` (a copy is handed out; the link keeps its own)."""

    state: str = "disconnected"
    identity: str = ""
    connects: int = 0
    disconnects: int = 0
    handshake_failures: int = 0
    samples: int = 0
    lost_samples: int = 0
    timeouts: int = 0
    bad_frames: dict = field(default_factory=dict)
    device_errors: int = 0
    severe_faults: int = 0
    last_device_error: str = ""
    last_link_error: str = ""
    writes: int = 0
    encode_errors: int = 0
    watchdog_active: bool = True
    commanded_v: float = math.nan
    applied_v: float = math.nan
    clipped: int = 0
    rejected: int = 0
    slew_limited: int = 0
    late_commands: int = 0
    held: int = 0
    expired: int = 0
    unexplained: int = 0
    ramp_errors: int = 0  # exceptions while ramping to v_safe at shutdown (the ramp went on)


class DeviceLink:
    """Drives one device: handshake, reconnect, limited voltage writes, polling, watchdog, health.

    Parameters
    ----------
    transport : SerialTransport
    adapter : Adapter
    limits : Limits
        ``dt_max`` should be one sample period, ``1/rate_hz``.
    rate_hz : int
        Sample rate (streamed by the device, or polled by the host).
    command_timeout : float
        No command for this long (s) → ramp to ``v_safe``.
    link_timeout : float
        No sample for this long (s) → close and reconnect.
    clock : callable
        Monotonic seconds (injectable for tests).
    """

    HANDSHAKE_TIMEOUT = 0.25
    HANDSHAKE_TRIES = 3

    def __init__(self, transport: SerialTransport, adapter: Adapter, limits: Limits, rate_hz: int, *,
                 command_timeout: float = 0.1, link_timeout: float = 0.5, err_poll_period: float = 0.1,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transport, self.adapter = transport, adapter
        self.limiter = VoltageLimiter(limits)
        self.period = 1.0 / float(rate_hz)
        self.rate_hz = int(rate_hz)
        self.watchdog = CommandWatchdog(command_timeout)
        self.link_timeout = float(link_timeout)
        self.sample_timeout = max(5 * self.period, 0.02)
        self.err_poll_period = err_poll_period
        self.clock = clock
        self.health = LinkHealth()
        self._pending_cmd: tuple[float, float] | None = None
        #: Set by :meth:`ramp_to_safe`: commands from then on are counted and never written.
        self.closing = False
        self._pending_limits: Limits | None = None
        self._last_write = -math.inf
        self._last_poll = -math.inf
        self._last_err_poll = -math.inf
        self._last_rx = -math.inf
        self._in_timeout = False
        #: Device time (s) of the newest running-state sample: a silence the host slept through shows as a gap.
        self._last_dev_t: float | None = None
        self._hs_deadline = 0.0
        self._hs_tries = 0
        self._seeded = False
        self._seed: tuple[float, int | None] | None = None  # last handshake read-back: (V, sample number)
        self.device_clock = DeviceClock()
        self._lock = threading.Lock()  # command() (executor thread) and service() (I/O thread) share the port
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)

    # ------------------------------------------------------------ inputs from other threads
    def command(self, volts: float, now: float | None = None) -> None:
        """A commanded voltage (thread-safe). While running it is limited and written at once, in the caller's
        thread (one thread hop less in the 1 kHz loop); otherwise it waits for the link to come up."""
        now = self.clock() if now is None else now
        with self._lock:
            if self.closing:  # the shutdown ramp owns the output (a late command landed after it at load 11)
                self.health.late_commands += 1
                return
            if self.health.state == "running" and self._pending_limits is None:
                if self.limiter.request(volts):  # a rejected command (NaN, 1e300) is not a sign of life
                    self.watchdog.feed(now)
                try:
                    self._write_voltage(now)
                except LinkError as err:
                    self._drop(str(err))
                return
            self._pending_cmd = (volts, now)
        self.wake()

    def set_limits(self, limits: Limits, command_timeout: float | None = None) -> None:
        """Queue new limits (applied by the I/O thread before its next write)."""
        self._pending_limits = limits
        if command_timeout is not None:
            self.watchdog.timeout = float(command_timeout)
        self.wake()

    def wake(self) -> None:
        try:
            os.write(self._wake_w, b"\0")
        except BlockingIOError:
            pass

    def wait(self, timeout: float) -> None:
        """Block until the port is readable, :meth:`command` was called, or ``timeout`` (s) passed."""
        fds = [self._wake_r]
        fd = self.transport.fileno()
        if fd is not None:
            fds.append(fd)
        try:
            ready, _, _ = select.select(fds, [], [], max(0.0, timeout))
        except (OSError, ValueError):  # the port fd vanished under us: service() will notice
            ready = []
        if self._wake_r in ready:
            try:
                os.read(self._wake_r, 4096)
            except BlockingIOError:
                pass

    def next_deadline(self) -> float:
        """Latest time :meth:`service` must run again without input: every sample while ramping or polling,
        else every 5 ms (timeouts, keepalive, reconnects) — streamed samples wake the I/O thread anyway, and
        fewer idle wake-ups leave the CPU to the rest of the 1 kHz loop."""
        busy = self.health.state != "running" or not self.limiter.settled or not self.adapter.streaming
        return self.clock() + (self.period if busy else max(self.period, 0.005))

    def close(self) -> None:
        self.transport.close()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # ------------------------------------------------------------ the work
    def snapshot(self) -> LinkHealth:
        """A copy of the health record, limiter counts included."""
        c = self.limiter.counts
        return replace(self.health, bad_frames=dict(self.health.bad_frames), clipped=c.clipped,
                       rejected=c.rejected, slew_limited=c.slew_limited, held=c.held, expired=c.expired,
                       unexplained=c.unexplained)

    def service(self, now: float | None = None) -> list[tuple[float, Reading]]:
        """Do everything that is due; return ``(sample_time, reading)`` pairs (sample time on :attr:`clock`:
        the device clock mapped by :class:`DeviceClock`, else the arrival time). Never raises on link trouble."""
        out: list[tuple[float, Reading]] = []
        with self._lock:
            now = self.clock() if now is None else now
            try:
                self._service(now, out)
            except LinkError as err:
                self._drop(str(err))
        return out

    def _drop(self, why: str) -> None:
        self.transport.close()
        if self.health.state != "disconnected":
            self.health.disconnects += 1
        self.health.state = "disconnected"
        self.health.last_link_error = why
        self._seeded = False

    def _service(self, now: float, out: list) -> None:
        h = self.health
        if self._pending_limits is not None:
            lim, self._pending_limits = self._pending_limits, None
            self.limiter.set_limits(lim)
        if h.state == "disconnected":
            if not self.transport.try_open(now):
                h.last_link_error = self.transport.last_error or h.last_link_error
                return
            self.adapter.reset()
            self.device_clock.reset()
            h.state, h.identity, self._seeded, self._hs_tries, self._seed = "handshake", "", False, 0, None
            self._last_dev_t = None
            self._send_handshake(now)
        data = self.transport.read()
        for ev in self.adapter.feed(data) if data else ():
            self._event(ev, now, out)
        h.lost_samples = self.adapter.lost_samples
        if h.state == "handshake":
            if h.identity and self._seeded:
                self.transport.write(self.adapter.start(self.rate_hz))
                h.state, h.connects = "running", h.connects + 1
                self._last_rx, self._in_timeout = now, False
            elif now > self._hs_deadline:
                if self._hs_tries >= self.HANDSHAKE_TRIES:
                    h.handshake_failures += 1
                    raise LinkError(f"no handshake answer from {self.transport.url}")
                self._send_handshake(now)
            return
        self._run(now)

    def _send_handshake(self, now: float) -> None:
        self._hs_tries += 1
        self._hs_deadline = now + self.HANDSHAKE_TIMEOUT
        self.adapter.reset()
        once = self.adapter.read_once
        self.transport.write(self.adapter.stop() + self.adapter.identify() + once() + once())

    def _event(self, ev, now: float, out: list) -> None:
        h = self.health
        if isinstance(ev, Reading):
            if h.state == "running" and ev.device_time is not None:
                # A device silence longer than sample_timeout is a timeout even when this host was stalled through
                # all of it (the samples after it then arrive at once and the arrival clock never saw a gap);
                # the device's own clock shows it. Gaps < 0 (clock wrap) or seen live already are not counted.
                gap = None if self._last_dev_t is None else ev.device_time - self._last_dev_t
                if gap is not None and gap > self.sample_timeout and not self._in_timeout:
                    h.timeouts += 1
                self._last_dev_t = ev.device_time
            self._last_rx, self._in_timeout = now, False
            h.applied_v = ev.applied_v
            if h.state == "handshake" and not self._seeded:
                if not h.identity:
                    # Produced before the device read the handshake (a stream still running from the last
                    # connection): a setpoint written before the link dropped may still be ahead of the
                    # handshake in the FIFO and be applied after these samples. The identify reply comes after
                    # the device has read all of it (measured at load 10: seeded from two such samples, the
                    # first write was judged from a voltage the amplifier had already left, a 21.1 V step).
                    return
                # Start from what the amplifier applies now (after a replug it may have reset to 0 V); two
                # agreeing read-backs, so one corrupted line of an unchecked protocol cannot seed the limiter.
                # With sample numbers they must come from different device samples: a setpoint that arrived
                # just before the link dropped is applied at the device's next tick, and two read-backs from
                # before it would seed the limiter with a voltage the amplifier is about to leave (seen once in
                # 600 injected faults: a 20.6 V step against a 20 V slew limit).
                prev, self._seed = self._seed, (ev.applied_v, ev.seq)
                if prev is None:
                    return
                if ev.seq is not None and ev.seq == prev[1]:
                    self.transport.write(self.adapter.read_once())  # again, after the next device sample
                    return
                if abs(ev.applied_v - prev[0]) <= 1e-3:
                    self.limiter.reset(ev.applied_v)
                    self._seeded = True
                elif ev.seq is not None:
                    self.transport.write(self.adapter.read_once())  # still moving (or corrupted): read again
                return
            h.samples += 1
            t = now if ev.device_time is None else self.device_clock.map(ev.device_time, now)
            out.append((t, ev))
            # The limiter learns what the amplifier applies, and when the sample was taken (that time only
            # serves to forget writes no read-back ever showed, so it must never be late): a polled reply was
            # taken after its poll left (a late reply to the previous poll, at most sample_timeout earlier); a
            # streamed sample's mapped time is trusted once the device clock has a full window, before that the
            # sample counts as taken at an unknown time (-inf: it expires nothing). Measured without that rule:
            # a write forgotten while still in flight after a reconnect at load 14, and a 30.1 V step.
            if ev.device_time is not None:
                t_taken = t if self.device_clock.settled else -math.inf
            else:
                t_taken = -math.inf if self.adapter.streaming else self._last_poll - self.sample_timeout
            self.limiter.observe(ev.applied_v, t_taken)
        elif isinstance(ev, BadFrame):
            h.bad_frames[ev.kind] = h.bad_frames.get(ev.kind, 0) + 1
        elif isinstance(ev, DeviceFault):
            h.device_errors += 1
            h.severe_faults += int(ev.severe)
            h.last_device_error = f"{ev.code}: {ev.text}"
        elif isinstance(ev, Identified) and h.state == "handshake":
            h.identity = ev.text  # later replies to *IDN? are GCS resynchronisation markers, not a new device

    def _write_voltage(self, now: float) -> None:
        v = self.limiter.step(now - self._last_write)
        if self.limiter.hold:  # the device has not yet confirmed enough to allow any new voltage: write nothing
            return
        try:
            data = self.adapter.set_voltage(v)
        except EncodeError:  # cannot happen for limiter output; counted, never sent
            self.health.encode_errors += 1
            return
        self.limiter.sent(now)  # before the bytes: a write that fails half-way may still reach the device
        self.transport.write(data)
        self._last_write = now
        self.health.writes += 1
        self.health.commanded_v = v

    def _run(self, now: float) -> None:
        h = self.health
        cmd, self._pending_cmd = self._pending_cmd, None
        if cmd is not None and self.limiter.request(cmd[0]):
            self.watchdog.feed(cmd[1])
        if self.watchdog.expired(now):
            self.limiter.request_safe()
            h.watchdog_active = True
        else:
            h.watchdog_active = False
        due = now - self._last_write >= self.period
        if cmd is not None or (not self.limiter.settled and due) or now - self._last_write >= 0.1:
            self._write_voltage(now)  # new command, ramp in progress (once per sample), or 10 Hz keepalive
        since_poll = now - self._last_poll
        if not self.adapter.streaming and since_poll >= self.period and \
                (not self.adapter.busy or since_poll >= self.sample_timeout):  # one exchange in flight
            self.transport.write(self.adapter.poll())
            self._last_poll = now
            if now - self._last_err_poll >= self.err_poll_period:
                self.transport.write(self.adapter.error_query())
                self._last_err_poll = now
        silent = now - self._last_rx
        if silent > self.sample_timeout and not self._in_timeout:
            h.timeouts += 1
            self._in_timeout = True
        if silent > self.link_timeout:
            raise LinkError(f"no sample for {silent:.3f} s")

    def ramp_to_safe(self, max_seconds: float = 5.0, sleep: Callable[[float], None] = time.sleep) -> bool:
        """Blocking: ramp the output to ``v_safe`` at the slew limit, then stop streaming (shutdown path).

        Returns True once the amplifier's read-back shows ``v_safe`` applied, False when the link was down or the
        time ran out. Written is not enough: under load a pty (and a USB serial bridge) can hold written bytes
        for a while, and closing the port then drops them — measured in 2 of 20 fault-test runs beside three CPU
        hogs, the device was left at 74 V and 51 V after "ramped" (there, the ramp had not even begun: see below).
        Until the read-back confirms, the link keeps servicing, so a write the device never applied is re-ramped
        from what it does apply.
        """
        with self._lock:
            self.closing = True
        self.watchdog.timeout = -1.0  # expired from now on: target is v_safe
        t_end = self.clock() + max_seconds
        while self.clock() < t_end:
            try:
                self.service()
            except Exception:  # noqa: BLE001 - a fault on the way down must not abort the ramp (device left at 150 V)
                self.health.ramp_errors += 1
                sleep(self.period)
                continue
            h, lim = self.health, self.limiter
            # the target must be v_safe itself: right after closing began, the limiter can still sit settled at
            # the last command (the watchdog's target reaches it on a later write), which once ended the "ramp"
            # with the device left at 74 V
            if h.state == "running" and lim.settled and abs(lim.target - lim.limits.v_safe) <= lim.limits.quantum \
                    and h.commanded_v == lim.value and abs(h.applied_v - lim.value) <= max(1e-3, lim.limits.quantum):
                try:
                    self.transport.write(self.adapter.stop())
                except LinkError:
                    pass
                return True
            sleep(self.period)
        return False
