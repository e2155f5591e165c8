"""Raw-message rosbag2 IO for the recorder and player (``rosbags``; no rclpy, no rosbag2_py).

Messages stay serialized CDR bytes end to end, so any type in the standard ROS 2 Jazzy typestore can be recorded
and replayed without deserialising. Bags are rosbag2 directories with MCAP storage and zstd chunk compression
(what ``ros2 bag`` on the rig reads). The analysis-level reader of ``/stage/state`` arrays is
:mod:`hyst_model.io.bag`.
"""
from __future__ import annotations

import importlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import BagError

if TYPE_CHECKING:  # pragma: no cover - typing only (rosbags is imported on first use)
    from rosbags.interfaces import Connection

__all__ = ["RawMessage", "RawBagWriter", "read_raw", "bag_topics", "message_class", "default_bag_path"]


@dataclass(frozen=True)
class RawMessage:
    """One recorded message: topic, type (``pkg/msg/Type``), receive time (ns) and serialized CDR bytes."""

    topic: str
    msgtype: str
    t_ns: int
    data: bytes


def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def default_bag_path(root: str | Path = "bags", prefix: str = "hyst") -> Path:
    """``bags/hyst_YYYYmmdd_HHMMSS`` (local time), made unique with a suffix if it exists."""
    import time

    base = Path(root) / f"{prefix}_{time.strftime('%Y%m%d_%H%M%S')}"
    p, i = base, 1
    while p.exists():
        p, i = base.with_name(f"{base.name}_{i}"), i + 1
    return p


def message_class(msgtype: str):
    """The rclpy message class of ``pkg/msg/Type`` (raises :class:`BagError` if not installed)."""
    try:
        pkg, kind, name = msgtype.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ValueError, ImportError, AttributeError):
        raise BagError(f"message type {msgtype!r} is not available in this Python environment") from None


class RawBagWriter:
    """Write serialized messages into a new rosbag2 directory (MCAP, zstd-compressed chunks).

    Parameters
    ----------
    path : path-like
        Bag directory to create; an existing path is refused (nothing is overwritten).
    compress : bool
        zstd chunk compression (default on).

    Use as a context manager, or call :meth:`close` (always, also after errors: it finalises the metadata).
    """

    def __init__(self, path: str | Path, compress: bool = True):
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists; choose a new output directory (nothing was overwritten)")
        if not self.path.parent.is_dir():
            raise BagError(f"{self.path.parent}: no such directory")
        self._ts = _typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            self._writer.open()
        except Exception as err:  # rosbags raises its own WriterError / OSError
            raise BagError(f"{self.path}: cannot create bag ({err})") from err
        self._conns: dict[str, Connection] = {}
        self.count = 0
        self._closed = False

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Register a topic (idempotent); the type must be in the standard ROS 2 Jazzy typestore."""
        if topic in self._conns:
            return
        if msgtype not in self._ts.fielddefs:
            raise BagError(f"{topic}: type {msgtype} is not a standard ROS 2 Jazzy message; cannot record it")
        self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=self._ts)

    @property
    def topics(self) -> tuple[str, ...]:
        return tuple(self._conns)

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        """Append one serialized message received at ``t_ns`` (ns since the epoch)."""
        self._writer.write(self._conns[topic], int(t_ns), bytes(data))
        self.count += 1

    def close(self) -> None:
        """Finalise the bag (metadata.yaml, MCAP summary); safe to call twice."""
        if not self._closed:
            self._closed = True
            self._writer.close()

    def __enter__(self) -> "RawBagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def bag_topics(path: str | Path) -> dict[str, str]:
    """``{topic: msgtype}`` of a bag."""
    from rosbags.rosbag2 import Reader

    try:
        with Reader(Path(path)) as r:
            return {c.topic: c.msgtype for c in r.connections}
    except Exception as err:
        raise BagError(f"{path}: cannot open bag ({type(err).__name__}: {err})") from err


def read_raw(path: str | Path, topics: Sequence[str] | None = None) -> Iterator[RawMessage]:
    """Messages of a bag in time order, still serialized; ``topics`` filters (unknown topics are an error)."""
    from rosbags.rosbag2 import Reader

    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag")
    try:
        reader = Reader(p)
        reader.open()
    except Exception as err:
        raise BagError(f"{p}: cannot open bag ({type(err).__name__}: {err})") from err
    try:
        conns = list(reader.connections)
        if topics:
            missing = set(topics) - {c.topic for c in conns}
            if missing:
                raise BagError(f"{p}: no topic(s) {', '.join(sorted(missing))} in the bag")
            conns = [c for c in conns if c.topic in set(topics)]
        for c, t_ns, data in reader.messages(connections=conns):
            yield RawMessage(c.topic, c.msgtype, int(t_ns), bytes(data))
    finally:
        reader.close()
