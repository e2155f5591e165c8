"""The serial port with reconnect (:class:`SerialTransport`) and the device's sample clock mapped to host time
(:class:`DeviceClock`). The port is injected (``opener``, default :func:`serial.serial_for_url`), so tests use
``loop://`` or a pty pair and the rig ``/dev/ttyACM0`` or a stable ``/dev/serial/by-id/...`` path.
:class:`hyst_driver.transport.DeviceLink` drives both; both are re-exported by :mod:`.transport`.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Callable

import serial

from .errors import LinkError

__all__ = ["SerialTransport", "DeviceClock"]


class DeviceClock:
    """Map a device's sample clock to the host clock, so stamps are sample times, not arrival times.

    ``host ≈ device + offset``. Every arrival bounds the offset from above (``host_rx - device`` includes the
    transfer latency), so the estimate is the smallest bound over a sliding window of ``window`` device seconds:
    host jitter (a busy machine reading late) does not reach the stamps, and crystal drift or a device that lost
    time is followed within one window. Device time wraps at ``wrap`` s (HDB/1: 2**32 µs).
    """

    def __init__(self, wrap: float = 2.0 ** 32 * 1e-6, window: float = 1.0) -> None:
        self.wrap, self.window = wrap, window
        self.reset()

    def reset(self) -> None:
        """Forget the mapping (the device restarted its clock, e.g. after a reconnect)."""
        self._last_raw: float | None = None
        self._turns = 0
        self._mins: deque[tuple[float, float]] = deque()  # (device time, bound), bounds increasing
        self._first: float | None = None  # device time of the first sample since the reset
        self._dev = -math.inf

    @property
    def settled(self) -> bool:
        """True once a whole window of device time has been mapped since :meth:`reset`. Before that the offset
        rests on few arrivals; if they all came late (a busy host after a reconnect), mapped times are late by
        as much — up to hundreds of ms at load 14 — so nothing that needs an upper bound may use them yet."""
        return self._first is not None and self._dev - self._first >= self.window

    def map(self, device_t: float, host_t: float) -> float:
        """Host time (same clock as ``host_t``) of the sample the device stamped ``device_t``."""
        if self._last_raw is not None and device_t < self._last_raw - 0.5 * self.wrap:
            self._turns += 1
        self._last_raw = device_t
        dev = device_t + self._turns * self.wrap
        if self._first is None:
            self._first = dev
        self._dev = dev
        bound = host_t - dev
        q = self._mins
        while q and q[-1][1] >= bound:  # monotonic deque: the window minimum is always q[0]
            q.pop()
        q.append((dev, bound))
        while q[0][0] < dev - self.window:
            q.popleft()
        return dev + q[0][1]


class SerialTransport:
    """A serial port that can vanish and come back.

    Parameters
    ----------
    url : str
        Anything :func:`serial.serial_for_url` opens: a device path, a pty path, ``loop://``.
    baudrate : int
        Ignored by ptys and USB-CDC devices; a UART needs ≥ 921600 for 1 kHz streaming.
    opener : callable
        ``opener(url, baudrate=..., timeout=..., write_timeout=...)`` returning a pyserial-like object.
    backoff : (float, float)
        First and largest delay (s) between reopen attempts; the delay doubles after each failure.
    """

    def __init__(self, url: str, baudrate: int = 921600, opener: Callable = serial.serial_for_url,
                 backoff: tuple[float, float] = (0.02, 0.5), write_timeout: float = 0.2) -> None:
        self.url, self.baudrate, self._opener = url, int(baudrate), opener
        self.backoff = backoff
        self.write_timeout = write_timeout
        self._port: Any = None  # the opener's pyserial-like object
        self._delay = backoff[0]
        self._next_try = -math.inf
        self.last_error = ""

    @property
    def is_open(self) -> bool:
        return self._port is not None

    def try_open(self, now: float) -> bool:
        """Open the port unless a backoff delay is pending; False (and a longer delay) on failure."""
        if self._port is not None:
            return True
        if now < self._next_try:
            return False
        try:
            self._port = self._opener(self.url, baudrate=self.baudrate, timeout=0,
                                      write_timeout=self.write_timeout)
        except (serial.SerialException, OSError, ValueError) as err:
            self.last_error = f"open {self.url}: {err}"
            self._next_try = now + self._delay
            self._delay = min(2 * self._delay, self.backoff[1])
            return False
        self._delay = self.backoff[0]
        try:
            self._port.reset_input_buffer()  # stale bytes from before a replug are not news
        except (serial.SerialException, OSError, AttributeError):
            pass
        return True

    def close(self) -> None:
        """Close (idempotent); the next :meth:`try_open` may follow after the shortest backoff."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass

    def fileno(self) -> int | None:
        """File descriptor to wait on, or None (``loop://`` has none)."""
        try:
            return self._port.fileno() if self._port is not None else None
        except (AttributeError, serial.SerialException, OSError, ValueError, NotImplementedError):
            return None

    def read(self) -> bytes:
        """Whatever has arrived (non-blocking). Raises :class:`LinkError` (and closes) when the port is gone."""
        if self._port is None:
            raise LinkError("port is closed")
        try:
            # read() itself (not in_waiting) notices a hung-up pty / unplugged USB device: EIO or "readiness
            # to read but returned no data" become SerialException.
            return self._port.read(4096)
        except (serial.SerialException, OSError) as err:
            self.close()
            self.last_error = f"read: {err}"
            raise LinkError(f"read from {self.url} failed: {err}") from err

    def write(self, data: bytes) -> None:
        """Write all of ``data``; raises :class:`LinkError` (and closes) on I/O errors or a stuck port."""
        if not data:
            return
        if self._port is None:
            raise LinkError("port is closed")
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as err:  # SerialTimeoutException is a SerialException
            self.close()
            self.last_error = f"write: {err}"
            raise LinkError(f"write to {self.url} failed: {err}") from err
