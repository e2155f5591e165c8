"""hyst_bag_record: record topics into a rosbag2 MCAP directory under ``bags/`` (``ros2 bag record`` stand-in).

Usage::

    hyst_bag_record [TOPIC[:TYPE] ...] [-o bags/run1] [--duration 10] [--no-compress]

Default topics: ``/stage/state /stage/command /stage/reference /controller/state``. Messages are stored as the
serialized CDR bytes that arrived (raw subscriptions: any standard message type), stamped with the receive time.
The contract topics of docs/ARCHITECTURE.md (and ``/diagnostics``) have known types and are subscribed at once;
other topics are subscribed when the ROS graph shows them (checked every 0.2 s; graph discovery can take
seconds next to a 1 kHz publisher, so give ``TOPIC:pkg/msg/Type`` to start at once). Subscriptions are reliable
(keep-all history) and switch to best effort when a best-effort publisher appears; callbacks only queue the bytes
and a writer thread writes them, so a slow disk or compression never makes the subscription drop samples.
SIGINT/SIGTERM or ``--duration`` stop recording and finalise the bag (metadata and MCAP summary). After a signal
the recorder first takes what the middleware has already delivered (until 0.3 s pass without a message, at most
3 s: a live stream is recorded up to 3 s past the signal; a second signal stops that at once), so a run that
ends faster than a loaded machine records keeps its tail; further
signals during finalisation are reported and ignored, so the bag is always readable. An existing output directory is
refused. To never miss the start of a lockstep run, start the recorder first and give the sim
``-p wait_for_subscribers:=2`` (it then waits for the recorder and the controller/excitation before sample 0);
the recorder prints ``recording`` once its contract-topic subscriptions exist.
"""
from __future__ import annotations

import argparse
import os
import queue
import signal
import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from hyst_common.node import run_node

from .bagio import RawBagWriter, default_bag_path, message_class
from .errors import BagError, SimError

__all__ = ["RecordNode", "DEFAULT_TOPICS", "main"]

DEFAULT_TOPICS = ("/stage/state", "/stage/command", "/stage/reference", "/controller/state")
_JS = "sensor_msgs/msg/JointState"
#: Types fixed by the contract (docs/ARCHITECTURE.md), so recording need not wait for graph discovery.
KNOWN_TYPES = {"/stage/state": _JS, "/stage/command": _JS, "/stage/reference": _JS, "/controller/state": _JS,
               "/model/prediction": _JS, "/model/residual": _JS,
               "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}


class RecordNode(Node):
    """Subscribe ``topics`` as they appear and write every message into ``writer``.

    Parameters
    ----------
    writer : RawBagWriter
        Open bag; the node writes into it, the caller closes it.
    topics : sequence of str
        Topics to record, each ``name`` or ``name:pkg/msg/Type``.
    duration : float or None
        Stop (``done`` becomes True) after this many seconds of recording.
    """

    def __init__(self, writer: RawBagWriter, topics=DEFAULT_TOPICS, duration: float | None = None, **kwargs):
        super().__init__("hyst_bag_record", **kwargs)
        self.writer = writer
        self.types: dict[str, str | None] = {}
        for t in topics:
            name, _, msgtype = t.partition(":")
            self.types[name] = msgtype or KNOWN_TYPES.get(name)
        self.wanted = tuple(self.types)
        self.duration = duration
        self.done = False
        self._subs: dict[str, Subscription | None] = {}  # None: the topic cannot be recorded
        self._best_effort: set[str] = set()
        self._t0 = time.monotonic()
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._wlock = threading.Lock()  # the bag writer is not thread-safe: add_topic (executor) vs write (thread)
        self._writer_thread = threading.Thread(target=self._drain, name="hyst_bag_writer", daemon=True)
        self._writer_thread.start()
        self.write_errors = 0
        self.received = 0  # messages taken from the middleware
        self.create_timer(0.2, self._discover)
        self._discover()

    def _drain(self) -> None:
        """Writer thread: write queued messages in arrival order until the ``None`` sentinel."""
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                with self._wlock:
                    self.writer.write(*item)
            except Exception as err:  # noqa: BLE001 - count and report, never kill the thread silently
                self.write_errors += 1
                self.get_logger().error(f"writing {item[0]} failed: {err}", throttle_duration_sec=1.0)

    def flush(self) -> None:
        """Stop taking messages and wait until every queued message is written (call before closing the bag)."""
        if self._writer_thread.is_alive():
            self._queue.put(None)
            self._writer_thread.join()

    def _discover(self) -> None:
        if self.duration is not None and time.monotonic() - self._t0 >= self.duration:
            self.done = True
            return
        graph = None
        for topic in self.wanted:
            if topic in self._subs:
                self._adapt_qos(topic)
                continue
            msgtype = self.types[topic]
            if msgtype is None:
                graph = graph if graph is not None else dict(self.get_topic_names_and_types())
                if topic not in graph:
                    continue
                msgtype = graph[topic][0]
            try:
                with self._wlock:
                    self.writer.add_topic(topic, msgtype)
                self._subscribe(topic, msgtype)
            except BagError as err:
                self.get_logger().error(str(err))
                self._subs[topic] = None  # do not retry every 0.2 s
                continue
            self.get_logger().info(f"recording {topic} ({msgtype})")

    def _subscribe(self, topic: str, msgtype: str) -> None:
        best = topic in self._best_effort
        qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                         reliability=ReliabilityPolicy.BEST_EFFORT if best else ReliabilityPolicy.RELIABLE)
        self.types[topic] = msgtype
        self._subs[topic] = self.create_subscription(message_class(msgtype), topic, self._writer_for(topic), qos,
                                                     raw=True)

    def _adapt_qos(self, topic: str) -> None:
        """A reliable subscription does not match a best-effort publisher: switch once one appears."""
        sub = self._subs[topic]
        if sub is None or topic in self._best_effort:
            return
        infos = self.get_publishers_info_by_topic(topic)
        if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos):
            msgtype = self.types[topic]
            if msgtype is None:  # _subscribe set it when it made the subscription
                raise SimError(f"{topic}: subscribed without a message type")
            self._best_effort.add(topic)
            self.destroy_subscription(sub)
            self._subscribe(topic, msgtype)
            self.get_logger().info(f"{topic}: best-effort publisher found, subscription switched to best effort")

    def _writer_for(self, topic: str):
        def write(data: bytes) -> None:
            self.received += 1
            self._queue.put((topic, self.get_clock().now().nanoseconds, data))
        return write


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="hyst_bag_record", description=__doc__.split("\n\n")[0])
    ap.add_argument("topics", nargs="*", default=list(DEFAULT_TOPICS),
                    help="TOPIC or TOPIC:pkg/msg/Type (default: %(default)s)")
    ap.add_argument("-o", "--output", type=Path, default=None,
                    help="bag directory to create (default: bags/hyst_<date>_<time>)")
    ap.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    ap.add_argument("--no-compress", action="store_true", help="store chunks uncompressed")
    a = ap.parse_args(argv)
    if a.duration is not None and not a.duration > 0:
        ap.error("--duration must be positive")
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_topic_name import validate_topic_name
    for item in a.topics:  # 'bad-topic' gave a traceback with a type and recorded nothing without one
        name, _, msgtype = item.partition(":")
        try:
            validate_topic_name(name)
        except InvalidTopicNameException:
            ap.error(f"{name!r} is not a valid ROS topic name (letters, digits, underscores and '/', each part not "
                     "starting with a digit)")
        if msgtype:  # a mistyped type recorded nothing and exited 0 with an empty bag
            try:
                message_class(msgtype)
            except BagError as err:
                ap.error(f"{name}: {err} (give TOPIC:pkg/msg/Type, e.g. /stage/state:sensor_msgs/msg/JointState)")
    return a


def main(args=None) -> int:
    """Console script ``hyst_bag_record``: :func:`hyst_common.node.run_node` with its own command line; the bag
    is finalised on every way out (signal, ``--duration``, an error in a callback)."""
    made: dict = {}

    def make(a: argparse.Namespace) -> RecordNode:
        out = a.output or default_bag_path()
        if a.output is None:
            try:
                out.parent.mkdir(parents=True, exist_ok=True)
            except OSError as err:  # ./bags is a file: a traceback before
                raise SimError(f"cannot create the bag folder {out.parent}: {err.strerror or err}; give -o PATH") \
                    from err
        writer = RawBagWriter(out, compress=not a.no_compress)  # refuses an existing directory
        try:
            node = RecordNode(writer, a.topics, a.duration)
        except BaseException:
            writer.close()
            raise
        made.update(node=node, out=out)
        print(f"hyst_bag_record: recording -> {out}", flush=True)
        return node

    def finish(node: RecordNode, stopped_by_signal: bool) -> None:
        if stopped_by_signal and rclpy.ok(context=node.context):
            _drain(node)
        _ignore_signals_while_finalising()
        if stopped_by_signal:
            print("hyst_bag_record: finalising the bag (further signals are ignored until it is written)",
                  file=sys.stderr, flush=True)
        node.flush()
        node.writer.close()  # always finalise the bag, also on SIGINT/SIGTERM

    code = run_node(make, args, prog="hyst_bag_record", parse=_parse, executor="single", errors=(SimError,),
                    until=lambda n: n.done, on_exit=finish)
    if threading.current_thread() is threading.main_thread() and args is None:
        # console script: a late signal must not kill the exiting interpreter (exit -2 after a good bag)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
    if "node" not in made:
        return code
    node = made["node"]
    writer = node.writer
    lost = f", {node.write_errors} write error(s)" if node.write_errors else ""
    print(f"hyst_bag_record: {writer.count} messages on {len(writer.topics)} topic(s) -> {made['out']}{lost}")
    return 1 if lost and code == 0 else code


def _drain(node: RecordNode, quiet: float = 0.3, longest: float = 3.0) -> None:
    """After the stop signal: take what the middleware already delivered, until ``quiet`` s pass without a
    message (or ``longest`` s — a live stream never goes quiet —, or a second signal). A lockstep run ends faster
    than a recorder on a loaded machine writes: stopping at once lost the last 3100 of 4000 samples of a demo
    bag."""
    again = [False]  # a second signal ends the drain; a plain flag: a handler must take no lock (Event.set does)

    def second(_s, _f) -> None:
        again[0] = True

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, second)
    print("hyst_bag_record: stopping: taking the messages already delivered (Ctrl-C again to stop at once)",
          file=sys.stderr, flush=True)
    executor = node.executor
    end = time.monotonic() + longest
    last, quiet_since = node.received, time.monotonic()
    while executor is not None and not again[0] and time.monotonic() < end and rclpy.ok(context=node.context):
        executor.spin_once(timeout_sec=0.05)
        if node.received != last:
            last, quiet_since = node.received, time.monotonic()
        elif time.monotonic() - quiet_since >= quiet:
            return


def _ignore_signals_while_finalising() -> None:
    """A second Ctrl-C must not interrupt writing the summary/metadata (that left an unreadable bag)."""
    def note(signum, _frame):
        # os.write, not print: a handler that prints while the main thread is printing raises a reentrant-call
        # RuntimeError from the buffered stream
        os.write(2, f"hyst_bag_record: {signal.Signals(signum).name} ignored: finalising the bag, please wait\n"
                 .encode())

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, note)


if __name__ == "__main__":
    raise SystemExit(main())
