"""HDB/1: the line-based ASCII protocol of the hyst DAQ bridge (a microcontroller between PC, amplifier and sensor).

Pure functions only (bytes in, values out); no I/O. Every frame is tested byte for byte in
``test/test_protocol_ascii.py``.

Frame
-----
::

    $<BODY>*<CC>\\r\\n

* ``BODY``: printable ASCII (0x20–0x7E) without ``$`` and ``*``; fields separated by ``,``; the first field is
  the message type. Integers are decimal, optional leading ``-``, no ``+``, no leading zeros.
* ``CC``: CRC-8 of the BODY bytes, two upper-case hex digits. CRC-8/SMBUS: polynomial 0x07, init 0x00, no
  reflection, no final XOR (check value ``crc8(b"123456789") == 0xF4``). Unlike an NMEA XOR it detects swapped
  and doubled characters and every burst error up to 8 bits.
* At most :data:`MAX_FRAME` bytes including ``$``, ``*CC`` and ``\\r\\n``. A receiver resynchronises on ``$``:
  bytes before the last ``$`` of a line are discarded (a truncated line spliced with the next one loses only
  the truncated frame).

Units on the wire are integers so frames are exact: voltage in microvolts (µV), position in sensor counts (the
host scales with ``counts_to_m``, e.g. 2 nm per count for the PEA stage), device time in microseconds.

Host → device
-------------
========================  =====================================  ==========================================
frame body                meaning                                 reply
========================  =====================================  ==========================================
``ID``                    identify                                ``ID,<vendor>,<model>,<serial>,<firmware>``
``SV,<uV>``               set the amplifier input voltage         none on success (the applied voltage is in
                                                                  every ``P`` sample); ``ER`` on failure
``RP``                    read one sample                         ``P,...``
``ST,<rate_hz>``          start streaming ``P`` at the rate       ``OK,ST,<rate_hz>`` then ``P`` lines
``SP``                    stop streaming                          ``OK,SP``
========================  =====================================  ==========================================

Device → host
-------------
* ``P,<seq>,<t_us>,<counts>,<uV>``: one sample. ``seq`` counts samples modulo 65536 (gaps reveal lost
  samples), ``t_us`` the device clock modulo 2**32, ``counts`` the sensor reading, ``uV`` the voltage the
  amplifier applies during this sample (after the device's own clamp).
* ``OK,<cmd>[,<arg>...]``: acknowledgement.
* ``ER,<code>,<text>``: error reply, codes in :data:`ERROR_CODES`.

Example: ``$SV,75000000*A5\\r\\n`` sets 75 V; ``$P,17,1017000,7500,75000000*07\\r\\n`` is a sample.
Streaming at 1 kHz carries ~35 kB/s: use USB-CDC or at least 921600 baud on a UART.

Length (~410 lines): the whole protocol — frame, CRC, every message's codec both ways and the line framer — in
one file, so that the spec above and its byte-exact implementation are read together.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Union

from .errors import ChecksumError, EncodeError, ProtocolError

__all__ = [
    "MAX_FRAME", "UV_PER_V", "UV_LIMIT", "ERROR_CODES", "crc8", "frame", "unframe",
    "Identify", "SetVoltage", "ReadPosition", "StartStream", "StopStream",
    "Identity", "Sample", "Ack", "ErrorReply",
    "encode_identify", "encode_set_voltage", "encode_read_position", "encode_start_stream", "encode_stop_stream",
    "encode_identity", "encode_sample", "encode_ack", "encode_error",
    "decode_reply", "decode_command", "volts_to_uv", "uv_to_volts", "LineFramer",
]

#: Longest frame allowed, bytes, ``$`` to ``\n`` inclusive.
MAX_FRAME = 96
#: Microvolts per volt: the wire unit of voltage.
UV_PER_V = 1_000_000
#: Largest |µV| a frame may carry (9 digits, ±999 V), far beyond any amplifier input.
UV_LIMIT = 999_999_999
#: Device error codes of ``ER`` replies.
ERROR_CODES: dict[int, str] = {
    1: "checksum error in received frame",
    2: "unknown command",
    3: "bad argument",
    4: "voltage outside the amplifier range",
    5: "amplifier fault (overload or over-temperature)",
    6: "sensor fault (signal lost or out of range)",
    7: "input buffer overflow",
}

_CRC_TABLE: tuple[int, ...] = ()


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        c = byte
        for _ in range(8):
            c = ((c << 1) ^ 0x07) & 0xFF if c & 0x80 else (c << 1) & 0xFF
        table.append(c)
    return tuple(table)


_CRC_TABLE = _make_table()
# \Z, not $: '$' also matches before a trailing newline ('ID\n' framed, '4\n' read as 4)
_INT = re.compile(rb"^(0|-?[1-9][0-9]*)\Z")
_HEX2 = re.compile(rb"^[0-9A-F]{2}\Z")
_BODY_OK = re.compile(rb"^[\x20-\x23\x25-\x29\x2b-\x7e]+\Z")  # printable without '$' (0x24) and '*' (0x2a)


def crc8(data: bytes) -> int:
    """CRC-8/SMBUS (poly 0x07, init 0, no reflection, no xorout) of ``data``."""
    c = 0
    for b in data:
        c = _CRC_TABLE[c ^ b]
    return c


# ---------------------------------------------------------------- framing
def frame(body: str) -> bytes:
    """Wrap a body as ``$BODY*CC\\r\\n``.

    Raises
    ------
    EncodeError
        The body has characters a frame cannot carry, or the frame would exceed :data:`MAX_FRAME`.
    """
    try:
        raw = body.encode("ascii")
    except UnicodeEncodeError:
        raw = b""
    if not raw or not _BODY_OK.match(raw):
        raise EncodeError(f"frame body {body!r} has characters outside printable ASCII or '$'/'*'")
    out = b"$" + raw + b"*%02X\r\n" % crc8(raw)
    if len(out) > MAX_FRAME:
        raise EncodeError(f"frame of {len(out)} bytes exceeds {MAX_FRAME}")
    return out


def unframe(line: bytes) -> list[bytes]:
    """Check a received line and return its body fields.

    ``line`` may still carry ``\\r\\n``; anything before the last ``$`` is discarded (resynchronisation).

    Raises
    ------
    ChecksumError
        The CRC does not match.
    ProtocolError
        No ``$``, no ``*CC``, bad characters, or too long.
    """
    line = line.rstrip(b"\r\n")
    start = line.rfind(b"$")
    if start < 0:
        raise ProtocolError(f"no frame start in {line[:40]!r}")
    line = line[start:]
    if len(line) + 2 > MAX_FRAME:
        raise ProtocolError(f"frame of {len(line) + 2} bytes exceeds {MAX_FRAME}")
    star = line.rfind(b"*")
    if star < 0 or len(line) - star != 3:
        raise ProtocolError(f"no '*CC' checksum in {line[:40]!r}")
    body, cc = line[1:star], line[star + 1:]
    if not body or not _BODY_OK.match(body):
        raise ProtocolError(f"bad characters in frame {line[:40]!r}")
    if not _HEX2.match(cc):
        raise ProtocolError(f"checksum {cc!r} is not two upper-case hex digits")
    if crc8(body) != int(cc, 16):
        raise ChecksumError(f"checksum {cc.decode('ascii', 'replace')} != {crc8(body):02X} in {line[:40]!r}")
    return body.split(b",")


def _int(field: bytes, name: str, lo: int, hi: int) -> int:
    if not _INT.match(field):
        raise ProtocolError(f"{name} {field[:20]!r} is not an integer")
    v = int(field)
    if not lo <= v <= hi:
        raise ProtocolError(f"{name} {v} outside [{lo}, {hi}]")
    return v


def _text(field: bytes) -> str:
    return field.decode("ascii")


# ---------------------------------------------------------------- messages
@dataclass(frozen=True)
class Identify:
    """Host asks who the device is (``ID``)."""


@dataclass(frozen=True)
class SetVoltage:
    """Host sets the amplifier input (``SV,<uV>``)."""

    uv: int


@dataclass(frozen=True)
class ReadPosition:
    """Host asks for one sample (``RP``)."""


@dataclass(frozen=True)
class StartStream:
    """Host starts streaming samples at ``rate_hz`` (``ST,<rate_hz>``)."""

    rate_hz: int


@dataclass(frozen=True)
class StopStream:
    """Host stops streaming (``SP``)."""


@dataclass(frozen=True)
class Identity:
    """Device identification (``ID,...`` reply)."""

    vendor: str
    model: str
    serial: str
    firmware: str


@dataclass(frozen=True)
class Sample:
    """One sample (``P,...``): sequence number, device time (µs), sensor counts, applied voltage (µV)."""

    seq: int
    t_us: int
    counts: int
    uv: int


@dataclass(frozen=True)
class Ack:
    """Acknowledgement (``OK,<cmd>[,<arg>...]``)."""

    command: str
    args: tuple[str, ...] = ()


@dataclass(frozen=True)
class ErrorReply:
    """Device error (``ER,<code>,<text>``)."""

    code: int
    text: str


Command = Union[Identify, SetVoltage, ReadPosition, StartStream, StopStream]
Reply = Union[Identity, Sample, Ack, ErrorReply]


# ---------------------------------------------------------------- encoders (host side)
def volts_to_uv(volts: float) -> int:
    """Volts to wire microvolts, rounded to nearest. Raises :class:`EncodeError` on non-finite or > 999 V."""
    if isinstance(volts, bool) or not isinstance(volts, (int, float)) or not math.isfinite(volts):
        raise EncodeError(f"voltage {volts!r} is not a finite number")
    if abs(volts) >= UV_LIMIT / UV_PER_V + 1.0:  # 1e303 V overflowed in round() before the range test
        raise EncodeError(f"voltage {volts!r} V does not fit the wire format (|V| < 1000)")
    uv = round(volts * UV_PER_V)
    if abs(uv) > UV_LIMIT:
        raise EncodeError(f"voltage {volts!r} V does not fit the wire format (|V| < 1000)")
    return int(uv)


def uv_to_volts(uv: int) -> float:
    """Wire microvolts to volts."""
    return uv / UV_PER_V


def encode_identify() -> bytes:
    """``$ID*CC``."""
    return frame("ID")


def encode_set_voltage(uv: int) -> bytes:
    """``$SV,<uV>*CC``. ``uv`` must already be limited (:mod:`hyst_driver.safety`); this only checks the format."""
    if isinstance(uv, bool) or not isinstance(uv, int) or abs(uv) > UV_LIMIT:
        raise EncodeError(f"set-voltage argument {uv!r} is not an integer microvolt value within ±{UV_LIMIT}")
    return frame(f"SV,{uv}")


def encode_read_position() -> bytes:
    """``$RP*CC``."""
    return frame("RP")


def encode_start_stream(rate_hz: int) -> bytes:
    """``$ST,<rate_hz>*CC`` with 1 ≤ rate_hz ≤ 10000."""
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, int) or not 1 <= rate_hz <= 10000:
        raise EncodeError(f"stream rate {rate_hz!r} must be an integer in [1, 10000] Hz")
    return frame(f"ST,{rate_hz}")


def encode_stop_stream() -> bytes:
    """``$SP*CC``."""
    return frame("SP")


# ---------------------------------------------------------------- encoders (device side, used by the emulator)
def encode_identity(ident: Identity) -> bytes:
    """``$ID,<vendor>,<model>,<serial>,<firmware>*CC``; fields must not contain ``,``."""
    fields = (ident.vendor, ident.model, ident.serial, ident.firmware)
    if any("," in f or not f for f in fields):
        raise EncodeError(f"identity fields must be non-empty without ',': {fields!r}")
    return frame("ID," + ",".join(fields))


def encode_sample(s: Sample) -> bytes:
    """``$P,<seq>,<t_us>,<counts>,<uV>*CC``."""
    if not (0 <= s.seq <= 0xFFFF and 0 <= s.t_us <= 0xFFFFFFFF and abs(s.counts) < 2**31
            and abs(s.uv) <= UV_LIMIT):
        raise EncodeError(f"sample {s!r} out of field ranges")
    return frame(f"P,{s.seq},{s.t_us},{s.counts},{s.uv}")


def encode_ack(command: str, *args: str) -> bytes:
    """``$OK,<command>[,<arg>...]*CC``."""
    return frame(",".join(("OK", command) + tuple(str(a) for a in args)))


def encode_error(code: int, text: str = "") -> bytes:
    """``$ER,<code>,<text>*CC``; ``text`` defaults to :data:`ERROR_CODES` and loses any ``,``."""
    if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 999:  # what decode_reply accepts
        raise EncodeError(f"error code {code!r} is not an integer in 0..999")
    text = (text or ERROR_CODES.get(code, "error")).replace(",", ";")
    return frame(f"ER,{code},{text}")


# ---------------------------------------------------------------- decoders
def decode_reply(line: bytes) -> Reply:
    """Decode a device → host line into :class:`Sample`, :class:`Identity`, :class:`Ack` or :class:`ErrorReply`.

    Raises
    ------
    ChecksumError, ProtocolError
    """
    f = unframe(line)
    kind = f[0]
    if kind == b"P":
        if len(f) != 5:
            raise ProtocolError(f"P frame has {len(f) - 1} fields, want 4")
        return Sample(_int(f[1], "seq", 0, 0xFFFF), _int(f[2], "t_us", 0, 0xFFFFFFFF),
                      _int(f[3], "counts", -(2**31) + 1, 2**31 - 1), _int(f[4], "uV", -UV_LIMIT, UV_LIMIT))
    if kind == b"ID":
        if len(f) != 5 or not all(f[1:]):
            raise ProtocolError("ID reply needs vendor, model, serial, firmware")
        return Identity(*(_text(x) for x in f[1:]))
    if kind == b"OK":
        if len(f) < 2 or not f[1]:
            raise ProtocolError("OK reply without command")
        return Ack(_text(f[1]), tuple(_text(x) for x in f[2:]))
    if kind == b"ER":
        if len(f) < 2:
            raise ProtocolError("ER reply without code")
        return ErrorReply(_int(f[1], "error code", 0, 999), _text(b",".join(f[2:])))
    raise ProtocolError(f"unknown reply type {kind[:8]!r}")


def decode_command(line: bytes) -> Command:
    """Decode a host → device line (the emulator's side). Raises :class:`ChecksumError`/:class:`ProtocolError`."""
    f = unframe(line)
    kind, n = f[0], len(f) - 1
    simple: dict[bytes, Callable[[], Command]] = {b"ID": Identify, b"RP": ReadPosition, b"SP": StopStream}
    if kind in simple:
        if n:
            raise ProtocolError(f"{kind.decode()} takes no argument")
        return simple[kind]()
    if kind == b"SV" and n == 1:
        return SetVoltage(_int(f[1], "uV", -UV_LIMIT, UV_LIMIT))
    if kind == b"ST" and n == 1:
        return StartStream(_int(f[1], "rate", 1, 10000))
    raise ProtocolError(f"unknown command or wrong arguments: {b','.join(f)[:30]!r}")


class LineFramer:
    """Split a byte stream into lines ending in ``\\n``; overlong lines are dropped, not buffered forever.

    Parameters
    ----------
    max_line : int
        Longest line kept (bytes). Longer input is discarded up to the next ``\\n`` and counted.
    start : bytes, optional
        A frame's first byte (HDB/1: ``$``): from an overlong line the part from its last ``start`` is kept when it
        fits — noise without a newline before a good frame cost the frame (72 bytes of it: the frame was dropped
        with the noise, 69 bytes: kept).
    """

    def __init__(self, max_line: int = MAX_FRAME, start: bytes | None = None) -> None:
        self.max_line = int(max_line)
        self.start = start
        self._buf = bytearray()
        self._skipping = False
        #: Lines dropped because they exceeded ``max_line``.
        self.overlong = 0

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the complete lines (without ``\\r\\n``)."""
        out: list[bytes] = []
        self._buf += data
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > self.max_line:
                    if not self._skipping:
                        self.overlong += 1
                    j = self._buf.rfind(self.start) if self.start else -1
                    if j > 0 and len(self._buf) - j <= self.max_line:  # a frame after the noise: keep it
                        del self._buf[:j]
                        self._skipping = False
                    else:
                        self._buf.clear()
                        self._skipping = True
                return out
            line = bytes(self._buf[:i]).rstrip(b"\r")
            del self._buf[:i + 1]
            skipped, self._skipping = self._skipping, False
            if skipped or len(line) > self.max_line:
                if not skipped:
                    self.overlong += 1
                j = line.rfind(self.start) if self.start else -1
                if j >= 0 and len(line) - j <= self.max_line:  # the frame that ends this line survives
                    out.append(line[j:])
                continue
            out.append(line)

    def reset(self) -> None:
        """Forget any partial line (after a reconnect)."""
        self._buf.clear()
        self._skipping = False
