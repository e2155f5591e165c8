"""A GCS-like command set, in the style of commercial piezo controllers (PI's General Command Set).

Pure functions only; tested byte for byte in ``test/test_protocol_gcs.py``. This is a second, deliberately
different protocol behind the same :class:`hyst_driver.adapter.Adapter` interface: polled instead of streamed,
no checksums, values as decimal text in controller units (V, µm), errors latched and read with ``ERR?``.
It is *GCS-like*: the handful of commands below follow GCS 2.0 syntax, but no real controller has been tested.

Lines end in ``\\n`` (LF). Axis (and output channel) identifier is ``1``.

==================  ==================================  ===============================
host sends          meaning                              device replies
==================  ==================================  ===============================
``*IDN?``           identify                             ``<vendor>,<model>,<serial>,<fw>``
``SVO 1 0``         servo off (open loop, required       nothing
                    before ``SVA``)
``SVA 1 <V>``       set open-loop value: amplifier       nothing (errors are latched)
                    input voltage (V)
``POS? 1``          position query (µm)                  ``1=<µm>``
``VOL? 1``          voltage actually applied (V)         ``1=<V>``
``ERR?``            read and clear the latched error     ``<code>``
==================  ==================================  ===============================

Error codes (GCS numbering where one exists): see :data:`ERROR_CODES`.
Without checksums a corrupted digit is undetectable; the driver's limiter therefore runs on what it sent, believes
a read-back that contradicts it only when read twice in a row, and rejects implausible read-backs. Replies carry no
query id: the adapter pairs them by counting and resynchronises on the reply to ``*IDN?`` (the only reply without
``=``) whenever the count breaks (:class:`hyst_driver.adapter.GcsAdapter`).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Union

from .errors import EncodeError, ProtocolError

__all__ = [
    "AXIS", "ERROR_CODES", "MAX_LINE", "VOLT_DECIMALS",
    "encode_idn", "encode_servo_off", "encode_sva", "encode_pos_query", "encode_vol_query", "encode_err_query",
    "AxisValue", "ErrorCode", "IdnReply", "decode_reply", "decode_command",
    "Idn", "ServoOff", "SetOpenLoop", "PosQuery", "VolQuery", "ErrQuery",
    "encode_axis_value", "encode_error_code", "encode_idn_reply",
]

AXIS = "1"
MAX_LINE = 96
#: Decimal places of the ``SVA`` argument: 1 µV resolution, the same grid as HDB/1.
VOLT_DECIMALS = 6
#: Latched error codes reported by ``ERR?``.
ERROR_CODES: dict[int, str] = {
    0: "no error",
    1: "parameter syntax error",
    2: "unknown command",
    3: "command too long",
    15: "invalid axis identifier",
    17: "parameter out of range",
    1000: "amplifier fault (overload or over-temperature)",
}

_NUM = re.compile(r"^-?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?$")
_INT = re.compile(r"^-?[0-9]+$")


def _ascii(line: bytes) -> str:
    if len(line) > MAX_LINE:
        raise ProtocolError(f"line of {len(line)} bytes exceeds {MAX_LINE}")
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError(f"non-ASCII bytes in {line[:40]!r}") from None
    text = text.rstrip("\r\n")
    if any(not (" " <= c <= "~") for c in text):
        raise ProtocolError(f"control characters in {line[:40]!r}")
    return text


def _number(s: str, what: str) -> float:
    if not _NUM.match(s):
        raise ProtocolError(f"{what} {s[:20]!r} is not a number")
    v = float(s)
    if not math.isfinite(v):
        raise ProtocolError(f"{what} {s[:20]!r} is not finite")
    return v


# ---------------------------------------------------------------- host → device
def encode_idn() -> bytes:
    """``*IDN?\\n``."""
    return b"*IDN?\n"


def encode_servo_off() -> bytes:
    """``SVO 1 0\\n``: open-loop operation, so that ``SVA`` drives the amplifier directly."""
    return b"SVO 1 0\n"


def encode_sva(volts: float) -> bytes:
    """``SVA 1 <V>\\n`` with :data:`VOLT_DECIMALS` decimals; ``volts`` must already be limited.

    Raises
    ------
    EncodeError
        Non-finite or |V| ≥ 1000.
    """
    if isinstance(volts, bool) or not isinstance(volts, (int, float)) or not math.isfinite(volts) \
            or abs(volts) >= 1000.0:
        raise EncodeError(f"SVA value {volts!r} is not a finite voltage below 1000 V")
    text = f"{volts:.{VOLT_DECIMALS}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]  # never send "-0.000000"
    return f"SVA {AXIS} {text}\n".encode("ascii")


def encode_pos_query() -> bytes:
    """``POS? 1\\n``."""
    return f"POS? {AXIS}\n".encode("ascii")


def encode_vol_query() -> bytes:
    """``VOL? 1\\n``."""
    return f"VOL? {AXIS}\n".encode("ascii")


def encode_err_query() -> bytes:
    """``ERR?\\n``."""
    return b"ERR?\n"


# ---------------------------------------------------------------- replies
@dataclass(frozen=True)
class AxisValue:
    """``<axis>=<value>`` reply to ``POS?`` or ``VOL?`` (which one is known only from the query order)."""

    axis: str
    value: float


@dataclass(frozen=True)
class ErrorCode:
    """Reply to ``ERR?``."""

    code: int


@dataclass(frozen=True)
class IdnReply:
    """Reply to ``*IDN?``: free text, conventionally ``vendor,model,serial,firmware``."""

    text: str


Reply = Union[AxisValue, ErrorCode, IdnReply]


def decode_reply(line: bytes, expect: str) -> Reply:
    """Decode a reply line given the query it answers (``"POS?"``, ``"VOL?"``, ``"ERR?"`` or ``"*IDN?"``).

    GCS replies do not say which query they answer; the caller pairs them with its queries in order.

    Raises
    ------
    ProtocolError
        Syntax does not match the expected reply.
    """
    text = _ascii(line)
    if expect in ("POS?", "VOL?"):
        axis, sep, value = text.partition("=")
        if not sep or axis != AXIS:
            raise ProtocolError(f"{expect} reply {text[:40]!r} is not '{AXIS}=<value>'")
        return AxisValue(axis, _number(value, f"{expect} value"))
    if expect == "ERR?":
        if not _INT.match(text):
            raise ProtocolError(f"ERR? reply {text[:40]!r} is not an integer")
        return ErrorCode(int(text))
    if expect == "*IDN?":
        if not text or "=" in text:
            raise ProtocolError(f"*IDN? reply {text[:40]!r} is empty or looks like a value reply")
        return IdnReply(text)
    raise ValueError(f"unknown query {expect!r}")


# ---------------------------------------------------------------- device side (emulator)
@dataclass(frozen=True)
class Idn:
    """``*IDN?``."""


@dataclass(frozen=True)
class ServoOff:
    """``SVO 1 0``."""


@dataclass(frozen=True)
class SetOpenLoop:
    """``SVA 1 <V>``."""

    volts: float


@dataclass(frozen=True)
class PosQuery:
    """``POS? 1``."""


@dataclass(frozen=True)
class VolQuery:
    """``VOL? 1``."""


@dataclass(frozen=True)
class ErrQuery:
    """``ERR?``."""


Command = Union[Idn, ServoOff, SetOpenLoop, PosQuery, VolQuery, ErrQuery]


def decode_command(line: bytes) -> Command:
    """Decode a host → device line. Raises :class:`ProtocolError` carrying the GCS error code in ``args[1]``."""
    text = _ascii(line).strip()
    parts = text.split()
    if not parts:
        raise ProtocolError("empty command", 1)
    cmd, args = parts[0], parts[1:]
    if cmd == "*IDN?" and not args:
        return Idn()
    if cmd == "ERR?" and not args:
        return ErrQuery()
    if cmd in ("POS?", "VOL?", "SVO", "SVA"):
        if not args or args[0] != AXIS:
            raise ProtocolError(f"{cmd}: invalid axis {args[:1]}", 15)
        if cmd == "POS?" and len(args) == 1:
            return PosQuery()
        if cmd == "VOL?" and len(args) == 1:
            return VolQuery()
        if cmd == "SVO" and len(args) == 2 and args[1] in ("0", "1"):
            if args[1] == "1":
                raise ProtocolError("closed-loop servo is not available", 17)
            return ServoOff()
        if cmd == "SVA" and len(args) == 2:
            return SetOpenLoop(_number(args[1], "SVA value"))
        raise ProtocolError(f"{cmd}: wrong arguments {args}", 1)
    raise ProtocolError(f"unknown command {cmd[:20]!r}", 2)


def encode_axis_value(value: float, decimals: int = 6) -> bytes:
    """``1=<value>\\n``."""
    if not math.isfinite(value):
        raise EncodeError(f"value {value!r} is not finite")
    return f"{AXIS}={value:.{decimals}f}\n".encode("ascii")


def encode_error_code(code: int) -> bytes:
    """``<code>\\n``."""
    return f"{int(code)}\n".encode("ascii")


def encode_idn_reply(text: str) -> bytes:
    """``<text>\\n``."""
    return text.encode("ascii") + b"\n"
