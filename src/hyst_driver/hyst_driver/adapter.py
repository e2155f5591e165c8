"""The one interface every device protocol implements, and its two implementations (HDB/1 ASCII, GCS-like).

An :class:`Adapter` is pure: it turns intentions into bytes (``set_voltage``, ``poll``, ...) and received bytes
into events (:meth:`Adapter.feed`); it never touches a port. Scaling to SI happens here and only here:
HDB/1 reports sensor counts (``position = counts · counts_to_m``) and microvolts; GCS reports µm and V.
Bad input never raises out of :meth:`Adapter.feed`: it becomes a :class:`BadFrame` event the driver counts.
"""
from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import Union, cast

from . import protocol_ascii as hdb
from . import protocol_gcs as gcs
from .errors import ChecksumError, ConfigError, ProtocolError

__all__ = ["Adapter", "AsciiAdapter", "GcsAdapter", "Reading", "Identified", "DeviceFault", "BadFrame",
           "Acknowledged", "Event", "make_adapter", "PROTOCOLS"]

#: A bare integer line (GCS ``ERR?`` answer): one optional minus sign, digits.
_INTEGER = re.compile(rb"-?[0-9]+")


@dataclass(frozen=True)
class Reading:
    """One sensor sample in SI: displacement (m), voltage the amplifier applies (V), optional sequence number and
    device clock (s, wrapping; None when the protocol has no time stamp)."""

    position_m: float
    applied_v: float
    seq: int | None = None
    device_time: float | None = None


@dataclass(frozen=True)
class Identified:
    """The device answered the identify request."""

    text: str


@dataclass(frozen=True)
class DeviceFault:
    """The device reported an error; ``severe`` for amplifier/sensor faults (not just a rejected command)."""

    code: int
    text: str
    severe: bool


@dataclass(frozen=True)
class BadFrame:
    """A received line was rejected: ``kind`` is ``checksum``, ``syntax``, ``garbage``, ``partial``, ``overlong``,
    ``unexpected`` or ``implausible``."""

    kind: str
    detail: str


@dataclass(frozen=True)
class Acknowledged:
    """The device acknowledged a command."""

    command: str


Event = Union[Reading, Identified, DeviceFault, BadFrame, Acknowledged]


class Adapter(ABC):
    """Protocol adapter interface.

    Parameters
    ----------
    v_plausible : (float, float)
        Range a read-back voltage must lie in to be believed (the profile range plus margin); a read-back
        outside it is reported as :class:`BadFrame` ``implausible`` (a corrupted line without checksum).
    """

    #: Protocol name used by the ``protocol`` parameter.
    name: str = ""
    #: True: the device streams samples at the rate by itself; False: the host polls every period.
    streaming: bool = False
    #: Voltage resolution on the wire (V).
    quantum: float = 1e-6

    def __init__(self, v_plausible: tuple[float, float] = (-1000.0, 1000.0)) -> None:
        self.v_plausible = (float(v_plausible[0]), float(v_plausible[1]))
        #: Samples missing according to sequence numbers (streaming protocols).
        self.lost_samples = 0

    @classmethod
    def create(cls, counts_to_m: float, v_plausible: tuple[float, float]) -> Adapter:
        """Build from the uniform arguments of :func:`make_adapter`; each protocol takes what it uses."""
        return cls(v_plausible)

    @abstractmethod
    def identify(self) -> bytes:
        """Bytes that ask the device to identify itself (answered by :class:`Identified`)."""

    @abstractmethod
    def start(self, rate_hz: int) -> bytes:
        """Bytes that put the device in operating mode at ``rate_hz`` (streaming or open-loop)."""

    @abstractmethod
    def stop(self) -> bytes:
        """Bytes that stop streaming (may be empty)."""

    @abstractmethod
    def set_voltage(self, volts: float) -> bytes:
        """Bytes that set the amplifier input. ``volts`` must come from :class:`hyst_driver.safety.VoltageLimiter`;
        raises :class:`hyst_driver.errors.EncodeError` if it cannot be encoded (never clips)."""

    @property
    def busy(self) -> bool:
        """True while replies to earlier queries are outstanding (polled protocols)."""
        return False

    @abstractmethod
    def poll(self) -> bytes:
        """Bytes that request one sample (empty for streaming protocols)."""

    @abstractmethod
    def read_once(self) -> bytes:
        """Bytes that request one sample even when streaming is off (handshake)."""

    @abstractmethod
    def error_query(self) -> bytes:
        """Bytes that ask for latched errors (empty when the device pushes them)."""

    @abstractmethod
    def feed(self, data: bytes) -> list[Event]:
        """Received bytes in, events out. Never raises on bad input."""

    @abstractmethod
    def reset(self) -> None:
        """Forget partial lines and pending queries (after a reconnect or a desynchronisation)."""

    def _plausible(self, v: float) -> bool:
        return self.v_plausible[0] <= v <= self.v_plausible[1]


class AsciiAdapter(Adapter):
    """HDB/1 (:mod:`hyst_driver.protocol_ascii`): streamed samples, CRC-8 frames, integer counts and µV.

    Parameters
    ----------
    counts_to_m : float
        Metres per sensor count (2e-9 for the 2 nm PEA sensor).
    """

    name = "ascii"
    streaming = True
    quantum = 1.0 / hdb.UV_PER_V

    @classmethod
    def create(cls, counts_to_m: float, v_plausible: tuple[float, float]) -> Adapter:
        """See :meth:`Adapter.create` (``counts_to_m``: metres per sensor count)."""
        return cls(counts_to_m, v_plausible)

    def __init__(self, counts_to_m: float = 2e-9, v_plausible: tuple[float, float] = (-1000.0, 1000.0)) -> None:
        super().__init__(v_plausible)
        if not counts_to_m > 0:
            raise ConfigError(f"counts_to_m must be positive, got {counts_to_m}")
        self.counts_to_m = float(counts_to_m)
        self._framer = hdb.LineFramer(start=b"$")
        self._last_seq: int | None = None

    def identify(self) -> bytes:
        return hdb.encode_identify()

    def start(self, rate_hz: int) -> bytes:
        self._last_seq = None  # the stream's first sample is no gap after the handshake's RP
        return hdb.encode_start_stream(int(rate_hz))

    def stop(self) -> bytes:
        return hdb.encode_stop_stream()

    def set_voltage(self, volts: float) -> bytes:
        return hdb.encode_set_voltage(hdb.volts_to_uv(volts))

    def poll(self) -> bytes:
        return b""

    def read_once(self) -> bytes:
        return hdb.encode_read_position()

    def error_query(self) -> bytes:
        return b""

    def reset(self) -> None:
        self._framer.reset()
        self._last_seq = None

    def feed(self, data: bytes) -> list[Event]:
        n_over = self._framer.overlong
        lines = self._framer.feed(data)
        events: list[Event] = [BadFrame("overlong", "line too long")] * (self._framer.overlong - n_over)
        for line in lines:
            if not line.strip():
                continue
            start = line.rfind(b"$")
            if not line.startswith(b"$"):  # noise before a frame start: reported, the frame may still be good
                events.append(BadFrame("garbage", f"{len(line) if start < 0 else start} bytes outside frames"))
            elif start > 0:  # a frame cut short, then the next one: the cut one is lost (and reported)
                events.append(BadFrame("partial", f"truncated frame {line[:min(start, 30)]!r}"))
            try:
                msg = hdb.decode_reply(line)
            except ChecksumError as err:
                events.append(BadFrame("checksum", str(err)))
                continue
            except ProtocolError as err:
                events.append(BadFrame("syntax", str(err)))
                continue
            if isinstance(msg, hdb.Sample):
                v = hdb.uv_to_volts(msg.uv)
                if not self._plausible(v):
                    events.append(BadFrame("implausible", f"applied voltage {v} V"))
                    continue
                if self._last_seq is not None and msg.seq != self._last_seq:  # equal: a re-read (RP), no gap
                    gap = (msg.seq - self._last_seq - 1) % 0x10000
                    if gap >= 0x8000:  # behind the last one (a late copy), not 65 534 samples lost
                        events.append(BadFrame("unexpected", f"sample {msg.seq} after {self._last_seq}"))
                        continue
                    self.lost_samples += gap
                self._last_seq = msg.seq
                events.append(Reading(msg.counts * self.counts_to_m, v, msg.seq, msg.t_us * 1e-6))
            elif isinstance(msg, hdb.Identity):
                events.append(Identified(f"{msg.vendor},{msg.model},{msg.serial},{msg.firmware}"))
            elif isinstance(msg, hdb.ErrorReply):
                events.append(DeviceFault(msg.code, msg.text, severe=msg.code in (5, 6)))
            else:
                events.append(Acknowledged(msg.command))
        return events


class GcsAdapter(Adapter):
    """GCS-like (:mod:`hyst_driver.protocol_gcs`): polled ``POS?``/``VOL?`` pairs, no checksums.

    GCS replies do not say which query they answer, so they are paired by counting: queries always go out in
    ``POS?``/``VOL?`` pairs and, while *synchronised*, the adapter knows exactly how many value lines it is owed,
    so the parity of that count says which one the next line answers. Anything that breaks the count — a line
    that does not decode (garbage spliced into a reply), a value line nobody asked for, a new poll while the
    last exchange still owes lines (a late device, a lost line) — desynchronises the adapter: value lines are
    then discarded (``unexpected``) until the reply to a ``*IDN?`` *marker*, which no value reply can look like;
    every poll sent while desynchronised carries one. Without it a late ``VOL?`` reply taken for the next
    ``POS?`` shifted every later pair by one line, and a position (µm) read as the applied voltage twice in a
    row re-seeded the slew limiter: a 69.6 V step reached the device (CI, garbage on the link).
    ``ERR?`` replies (bare integers) are taken out of band, in any state. Positions are in µm.
    """

    name = "gcs"
    streaming = False
    quantum = 10.0 ** -gcs.VOLT_DECIMALS
    #: Metres per GCS position unit (µm).
    POSITION_UNIT_M = 1e-6
    #: Markers remembered while their replies are outstanding (more means some were lost; the oldest go).
    MAX_MARKERS = 8

    def __init__(self, v_plausible: tuple[float, float] = (-1000.0, 1000.0)) -> None:
        super().__init__(v_plausible)
        self._framer = hdb.LineFramer(gcs.MAX_LINE)
        self._markers: deque[int] = deque(maxlen=self.MAX_MARKERS)  # POS?/VOL? pairs sent after each marker
        self._synced = False
        self._owed = 0  # value lines still owed while synchronised (even: the next one answers POS?)
        self._wait = False  # a marker is out and nothing since could have been its garbled reply
        self._pos: float | None = None

    @property
    def synchronised(self) -> bool:
        """True while replies can be paired with queries (see the class docstring)."""
        return self._synced

    def identify(self) -> bytes:
        self._marker()
        return gcs.encode_idn()

    def start(self, rate_hz: int) -> bytes:
        return gcs.encode_servo_off()

    def stop(self) -> bytes:
        return b""

    def set_voltage(self, volts: float) -> bytes:
        return gcs.encode_sva(volts)

    @property
    def busy(self) -> bool:
        """True while replies to the last queries are still outstanding, or a marker's reply is awaited. Not
        after a line that did not decode (it may have been that reply: a garbage burst's tail splices into the
        next line, often the marker's reply, which cost a sample timeout per burst): the next poll goes at once
        and carries another marker."""
        return self._owed > 0 or self._wait

    def _marker(self) -> None:
        self._desync()
        self._wait = True
        self._markers.append(0)

    def _pair(self) -> bytes:
        """One POS?/VOL? pair, counted where its replies will be paired; a marker first if nothing can be."""
        marker = b""
        if not self._synced and not self._markers:
            self._marker()
            marker = gcs.encode_idn()
        if self._synced:
            self._owed += 2
        else:
            self._markers[-1] += 1
        return marker + gcs.encode_pos_query() + gcs.encode_vol_query()

    def poll(self) -> bytes:
        if self._synced and self._owed == 0:
            return self._pair()
        # The last exchange still owes lines (late, or lost): whether they will come is unknown, so resynchronise.
        self._marker()
        return gcs.encode_idn() + self._pair()

    def read_once(self) -> bytes:
        return self._pair()  # queued behind a pending *IDN? (handshake), not replacing it

    def error_query(self) -> bytes:
        return gcs.encode_err_query()  # answered by a bare integer, taken out of band

    def reset(self) -> None:
        self._framer.reset()
        self._markers.clear()
        self._desync()

    def _desync(self) -> None:
        self._synced, self._owed, self._pos, self._wait = False, 0, None, False

    def feed(self, data: bytes) -> list[Event]:
        n_over = self._framer.overlong
        lines = self._framer.feed(data)
        events: list[Event] = [BadFrame("overlong", "line too long")] * (self._framer.overlong - n_over)
        if self._framer.overlong > n_over:
            self._desync()
        for line in lines:
            if line.strip():
                self._line(line, events)
        return events

    def _line(self, line: bytes, events: list[Event]) -> None:
        text = line.strip()
        if _INTEGER.fullmatch(text):  # (lstrip('-').isdigit() let '--5' through to int(): a ValueError out of feed)
            # A bare integer can only answer ERR?: taken in any order (late after a busy spell), because the
            # device cleared its latched error when it answered — dropping it would lose it.
            code = int(text)
            if code != 0:
                events.append(DeviceFault(code, gcs.ERROR_CODES.get(code, "error"), severe=code >= 1000))
            return
        if b"=" not in line:  # the only reply without '=': *IDN?, the marker
            try:
                idn = cast(gcs.IdnReply, gcs.decode_reply(line, "*IDN?"))
            except ProtocolError as err:
                events.append(BadFrame("syntax", str(err)))
                self._desync()
                return
            if not self._markers:  # nobody asked: the count cannot be trusted either
                events.append(BadFrame("unexpected", f"identity {idn.text[:30]!r} to no query"))
                self._desync()
                return
            events.append(Identified(idn.text))
            self._synced, self._owed, self._pos, self._wait = True, 2 * self._markers.popleft(), None, False
            return
        if not self._synced:  # late lines before the marker's reply: expected, the wait goes on
            events.append(BadFrame("unexpected", f"reply {line[:30]!r} discarded until resynchronised"))
            return
        if self._owed == 0:
            events.append(BadFrame("unexpected", f"reply {line[:30]!r} to no query"))
            self._desync()
            return
        expect = "POS?" if self._owed % 2 == 0 else "VOL?"
        try:
            value = cast(gcs.AxisValue, gcs.decode_reply(line, expect)).value
        except ProtocolError as err:
            events.append(BadFrame("syntax", str(err)))
            self._desync()
            return
        self._owed -= 1
        if expect == "POS?":
            self._pos = value * self.POSITION_UNIT_M
            return
        pos, self._pos = self._pos, None
        if pos is None:  # cannot happen while the count holds; kept so that a defect shows as a bad frame
            events.append(BadFrame("unexpected", "VOL? reply without POS?"))
        elif not self._plausible(value):
            events.append(BadFrame("implausible", f"applied voltage {value} V"))
        else:
            events.append(Reading(pos, value, None))


#: The protocols by name (a registry as data: :func:`make_adapter` and the ``protocol`` parameter read it). Adding
#: one is its codec module, its :class:`Adapter` subclass, and one line here.
PROTOCOLS: dict[str, type[Adapter]] = {
    "ascii": AsciiAdapter,
    "gcs": GcsAdapter,
}


def make_adapter(protocol: str, counts_to_m: float = 2e-9,
                 v_plausible: tuple[float, float] = (-1000.0, 1000.0)) -> Adapter:
    """Adapter by name. ``counts_to_m`` applies to ``ascii`` only (GCS reports µm).

    Raises
    ------
    ConfigError
        Unknown protocol name.
    """
    cls = PROTOCOLS.get(protocol)
    if cls is None:
        raise ConfigError(f"unknown protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    return cls.create(counts_to_m, v_plausible)
