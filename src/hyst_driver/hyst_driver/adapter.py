"""The one interface every device protocol implements, and its two implementations (HDB/1 ASCII, GCS-like).

An :class:`Adapter` is pure: it turns intentions into bytes (``set_voltage``, ``poll``, ...) and received bytes
into events (:meth:`Adapter.feed`); it never touches a port. Scaling to SI happens here and only here:
HDB/1 reports sensor counts (``position = counts · counts_to_m``) and microvolts; GCS reports µm and V.
Bad input never raises out of :meth:`Adapter.feed`: it becomes a :class:`BadFrame` event the driver counts.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import Union, cast

from . import protocol_ascii as hdb
from . import protocol_gcs as gcs
from .errors import ChecksumError, ConfigError, ProtocolError

__all__ = ["Adapter", "AsciiAdapter", "GcsAdapter", "Reading", "Identified", "DeviceFault", "BadFrame",
           "Acknowledged", "Event", "make_adapter", "PROTOCOLS"]


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
        self._framer = hdb.LineFramer()
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
                    self.lost_samples += (msg.seq - self._last_seq - 1) % 0x10000
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

    Replies are paired with queries in order; any bad line drops the pending queries (the rest of that
    exchange is discarded as ``unexpected``) so a lost line cannot shift later pairs. Positions are in µm.
    """

    name = "gcs"
    streaming = False
    quantum = 10.0 ** -gcs.VOLT_DECIMALS
    #: Metres per GCS position unit (µm).
    POSITION_UNIT_M = 1e-6

    def __init__(self, v_plausible: tuple[float, float] = (-1000.0, 1000.0)) -> None:
        super().__init__(v_plausible)
        self._framer = hdb.LineFramer(gcs.MAX_LINE)
        self._pending: deque[str] = deque()
        self._pos: float | None = None

    def identify(self) -> bytes:
        self._pending.append("*IDN?")
        return gcs.encode_idn()

    def start(self, rate_hz: int) -> bytes:
        return gcs.encode_servo_off()

    def stop(self) -> bytes:
        return b""

    def set_voltage(self, volts: float) -> bytes:
        return gcs.encode_sva(volts)

    @property
    def busy(self) -> bool:
        """True while replies to the last queries are still outstanding."""
        return bool(self._pending)

    def poll(self) -> bytes:
        # A new exchange: whatever the last one still owes is late; late lines are 'unexpected', not mispaired.
        self._pending.clear()
        self._pos = None
        self._pending.extend(("POS?", "VOL?"))
        return gcs.encode_pos_query() + gcs.encode_vol_query()

    def read_once(self) -> bytes:
        self._pending.extend(("POS?", "VOL?"))  # queued behind a pending *IDN? (handshake), not replacing it
        return gcs.encode_pos_query() + gcs.encode_vol_query()

    def error_query(self) -> bytes:
        self._pending.append("ERR?")
        return gcs.encode_err_query()

    def reset(self) -> None:
        self._framer.reset()
        self._pending.clear()
        self._pos = None

    def feed(self, data: bytes) -> list[Event]:
        n_over = self._framer.overlong
        lines = self._framer.feed(data)
        events: list[Event] = [BadFrame("overlong", "line too long")] * (self._framer.overlong - n_over)
        if self._framer.overlong > n_over:
            self._pending.clear()
        for line in lines:
            if not line.strip():
                continue
            if line.strip().lstrip(b"-").isdigit():
                # A bare integer can only answer ERR?: take it even out of order (late after a busy spell),
                # because the device cleared its latched error when it answered — dropping it would lose it.
                if "ERR?" in self._pending:
                    self._pending.remove("ERR?")
                code = int(line)
                if code != 0:
                    events.append(DeviceFault(code, gcs.ERROR_CODES.get(code, "error"), severe=code >= 1000))
                continue
            if not self._pending:
                events.append(BadFrame("unexpected", f"reply {line[:30]!r} to no query"))
                continue
            expect = self._pending.popleft()
            try:
                msg = gcs.decode_reply(line, expect)
            except ProtocolError as err:
                events.append(BadFrame("syntax", str(err)))
                self._pending.clear()
                self._pos = None
                continue
            # decode_reply's reply type follows from the query: AxisValue (POS?/VOL?), ErrorCode, IdnReply
            if expect == "POS?":
                self._pos = cast(gcs.AxisValue, msg).value * self.POSITION_UNIT_M
            elif expect == "VOL?":
                volts = cast(gcs.AxisValue, msg).value
                if self._pos is None:
                    events.append(BadFrame("unexpected", "VOL? reply without POS?"))
                elif not self._plausible(volts):
                    events.append(BadFrame("implausible", f"applied voltage {volts} V"))
                else:
                    events.append(Reading(self._pos, volts, None))
                self._pos = None
            elif expect == "ERR?":
                err_code = cast(gcs.ErrorCode, msg).code
                if err_code != 0:
                    events.append(DeviceFault(err_code, gcs.ERROR_CODES.get(err_code, "error"),
                                              severe=err_code >= 1000))
            else:
                events.append(Identified(cast(gcs.IdnReply, msg).text))
        return events


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
