"""hyst_driver: serial driver for the PEA/GMA amplifier and displacement sensor, protocol adapters, emulator.

Layers: pure protocol modules (:mod:`.protocol_ascii` HDB/1, :mod:`.protocol_gcs` GCS-like) behind one
:class:`~.adapter.Adapter` interface; :mod:`.safety` (the only place voltage limits are enforced);
:mod:`.transport` (injected serial transport, reconnect, :class:`~.transport.DeviceLink`); :mod:`.emulator`
(fake device on a pty, driven by ``hyst_sim.plant``); ``driver_node`` (the thin rclpy node, the only module
importing rclpy).
"""
import hyst_common  # noqa: F401  first: sets single-threaded BLAS before numpy loads (hyst_common.blas)

from .adapter import PROTOCOLS, Adapter, AsciiAdapter, BadFrame, DeviceFault, GcsAdapter, Reading, make_adapter
from .errors import ChecksumError, ConfigError, DriverError, EncodeError, LinkError, ProtocolError
from .safety import CommandWatchdog, Limits, VoltageLimiter
from .transport import DeviceClock, DeviceLink, LinkHealth, SerialTransport

__all__ = [
    "PROTOCOLS", "Adapter", "AsciiAdapter", "GcsAdapter", "Reading", "BadFrame", "DeviceFault", "make_adapter",
    "DriverError", "ProtocolError", "ChecksumError", "EncodeError", "LinkError", "ConfigError",
    "Limits", "VoltageLimiter", "CommandWatchdog",
    "SerialTransport", "DeviceLink", "LinkHealth", "DeviceClock",
]
