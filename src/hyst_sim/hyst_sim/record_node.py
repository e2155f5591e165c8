"""hyst_bag_record: record topics into a rosbag2 MCAP directory under ``bags/`` (``ros2 bag record`` stand-in).

Usage::

    hyst_bag_record [TOPIC ...] [-o bags/run1] [--duration 10] [--no-compress]

Default topics: ``/stage/state /stage/command /stage/reference /controller/state``. Topics are subscribed when
they appear (checked every 0.2 s) with raw subscriptions, so messages are stored as the serialized CDR bytes that
arrived (any standard message type), stamped with the receive time. The QoS follows the publishers (best effort
if any publisher is best effort, else reliable). SIGINT/SIGTERM or ``--duration`` stop recording and finalise
the bag (metadata and MCAP summary); an existing output directory is refused.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from .bagio import RawBagWriter, default_bag_path, message_class
from .errors import BagError, SimError

__all__ = ["RecordNode", "DEFAULT_TOPICS", "main"]

DEFAULT_TOPICS = ("/stage/state", "/stage/command", "/stage/reference", "/controller/state")


class RecordNode(Node):
    """Subscribe ``topics`` as they appear and write every message into ``writer``.

    Parameters
    ----------
    writer : RawBagWriter
        Open bag; the node writes into it, the caller closes it.
    topics : sequence of str
        Topics to record.
    duration : float or None
        Stop (``done`` becomes True) after this many seconds of recording.
    """

    def __init__(self, writer: RawBagWriter, topics=DEFAULT_TOPICS, duration: float | None = None, **kwargs):
        super().__init__("hyst_bag_record", **kwargs)
        self.writer = writer
        self.wanted = tuple(dict.fromkeys(topics))
        self.duration = duration
        self.done = False
        self._subs: dict[str, object] = {}
        self._t0 = time.monotonic()
        self.create_timer(0.2, self._discover)
        self._discover()

    def _discover(self) -> None:
        if self.duration is not None and time.monotonic() - self._t0 >= self.duration:
            self.done = True
            return
        types = dict(self.get_topic_names_and_types())
        for topic in self.wanted:
            if topic in self._subs or topic not in types:
                continue
            msgtype = types[topic][0]
            try:
                cls = message_class(msgtype)
                self.writer.add_topic(topic, msgtype)
            except BagError as err:
                self.get_logger().error(str(err))
                self._subs[topic] = None  # do not retry every 0.2 s
                continue
            infos = self.get_publishers_info_by_topic(topic)
            best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                             else ReliabilityPolicy.RELIABLE)
            self._subs[topic] = self.create_subscription(cls, topic, self._writer_for(topic), qos, raw=True)
            self.get_logger().info(f"recording {topic} ({msgtype})")

    def _writer_for(self, topic: str):
        def write(data: bytes) -> None:
            self.writer.write(topic, self.get_clock().now().nanoseconds, data)
        return write


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="hyst_bag_record", description=__doc__.split("\n\n")[0])
    ap.add_argument("topics", nargs="*", default=list(DEFAULT_TOPICS), help="topics (default: %(default)s)")
    ap.add_argument("-o", "--output", type=Path, default=None,
                    help="bag directory to create (default: bags/hyst_<date>_<time>)")
    ap.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    ap.add_argument("--no-compress", action="store_true", help="store chunks uncompressed")
    a = ap.parse_args(argv)
    if a.duration is not None and not a.duration > 0:
        ap.error("--duration must be positive")
    return a


def main(args=None) -> int:
    """Console script ``hyst_bag_record``."""
    from rclpy.utilities import remove_ros_args

    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    a = _parse(argv)
    out = a.output or default_bag_path()
    try:
        if a.output is None:
            out.parent.mkdir(parents=True, exist_ok=True)
        writer = RawBagWriter(out, compress=not a.no_compress)
    except SimError as err:
        print(f"hyst_bag_record: {err}", file=sys.stderr)
        return 2
    rclpy.init(args=args)
    node = None
    try:
        node = RecordNode(writer, a.topics, a.duration)
        while rclpy.ok() and not node.done:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        writer.close()  # always finalise the bag, also on SIGINT/SIGTERM
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    print(f"hyst_bag_record: {writer.count} messages on {len(writer.topics)} topic(s) -> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
