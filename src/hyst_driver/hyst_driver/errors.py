"""Exceptions of hyst_driver, all derived from :class:`DriverError` (itself a :class:`hyst_common.errors.HystError`).

Nodes catch these: a bad frame or a lost port is counted and reported on ``/diagnostics``, never fatal.
"""
from __future__ import annotations

from hyst_common.errors import HystError

__all__ = ["DriverError", "ProtocolError", "ChecksumError", "EncodeError", "LinkError",
           "ConfigError"]


class DriverError(HystError):
    """Base class of every hyst_driver error."""


class ProtocolError(DriverError):
    """A received line is not a valid frame (syntax, unknown message, wrong field count, too long)."""


class ChecksumError(ProtocolError):
    """A frame's checksum does not match its body (bit error, truncation spliced with another line)."""


class EncodeError(DriverError):
    """A value cannot be put on the wire (non-finite, out of the field's range). Never sent, never clipped."""


class LinkError(DriverError):
    """The serial link cannot be opened, was lost (port vanished, I/O error) or stopped answering."""


class ConfigError(DriverError):
    """Invalid driver configuration (limits outside the profile, unknown protocol, bad rate)."""
