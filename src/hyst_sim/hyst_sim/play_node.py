"""hyst_bag_play: replay a rosbag2 bag's topics with the original timing (``ros2 bag play`` stand-in).

Usage::

    hyst_bag_play BAG [--topics /stage/state ...] [--rate 1.0] [--loop] [--delay 0.5] [--wait-for-subscribers]

Messages are published as the recorded serialized bytes (headers and stamps unchanged) at their recorded
receive times relative to the first message, divided by ``--rate``. A player thread sleeps until each message
is due (sub-millisecond on Linux) while the main thread spins the node; if it falls behind it publishes the
late messages at once rather than dropping them. ``--loop`` repeats until SIGINT/SIGTERM.
"""
from __future__ import annotations

import argparse
import math
import threading
import time
from pathlib import Path

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy

from hyst_common.node import run_node

from .bagio import RawMessage, message_class, read_raw
from .errors import BagError, SimError

__all__ = ["PlayNode", "main"]


class PlayNode(Node):
    """Publish a list of raw messages with their relative timing on a player thread.

    Parameters
    ----------
    messages : list of RawMessage
        In time order (as :func:`hyst_sim.bagio.read_raw` yields them).
    rate : float
        Playback speed factor (2.0 = twice as fast).
    loop : bool
        Start again after the last message.
    delay : float
        Seconds to wait before the first message (discovery).
    wait_for_subscribers : float
        If > 0, wait up to this many seconds until every topic has a subscriber before starting.
    """

    def __init__(self, messages: list[RawMessage], rate: float = 1.0, loop: bool = False, delay: float = 0.0,
                 wait_for_subscribers: float = 0.0, **kwargs):
        super().__init__("hyst_bag_play", **kwargs)
        if not messages:
            raise BagError("the bag holds no messages to play")
        if not rate > 0:
            raise BagError("--rate must be positive")
        self.messages, self.rate, self.loop = messages, float(rate), bool(loop)
        self.delay, self.wait = float(delay), float(wait_for_subscribers)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self._pubs: dict[str, Publisher] = {}
        for m in messages:
            if m.topic not in self._pubs:
                self._pubs[m.topic] = self.create_publisher(message_class(m.msgtype), m.topic, qos)
        self.published = 0
        #: (index in ``messages``, seconds after its pass's start it was due, seconds after it was published): what
        #: the player aimed at and did, for tests and diagnostics (a message is never published before it is due)
        self.sent: list[tuple[int, float, float]] = []
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._play, name="hyst_bag_play", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _play(self) -> None:
        try:
            end = time.monotonic() + self.wait
            while self.wait > 0 and time.monotonic() < end and not self._stop.is_set():
                if all(p.get_subscription_count() > 0 for p in self._pubs.values()):
                    break
                time.sleep(0.01)
            if self._stop.wait(self.delay):
                return
            t_first = self.messages[0].t_ns
            while not self._stop.is_set():
                start = time.monotonic()
                for i, m in enumerate(self.messages):
                    due = start + (m.t_ns - t_first) * 1e-9 / self.rate
                    wait = due - time.monotonic()
                    while wait > 0:  # Event.wait may return a little early: never publish before the due time
                        if self._stop.wait(wait):
                            return
                        wait = due - time.monotonic()
                    self._pubs[m.topic].publish(m.data)
                    self.published += 1
                    if len(self.sent) < 100_000:  # bounded: a looping player runs for hours
                        self.sent.append((i, due - start, time.monotonic() - start))
                if not self.loop:
                    return
        finally:
            self.done.set()


#: Longest --delay or --wait-for-subscribers (s): a day.
MAX_WAIT = 86400.0


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="hyst_bag_play", description=__doc__.split("\n\n")[0])
    ap.add_argument("bag", type=Path, help="rosbag2 directory (MCAP or sqlite3)")
    ap.add_argument("--topics", nargs="+", default=None, help="only these topics")
    ap.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1.0)")
    ap.add_argument("--loop", action="store_true", help="repeat until interrupted")
    ap.add_argument("--delay", type=float, default=0.5, help="seconds before the first message (default 0.5)")
    ap.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                    help="wait up to S seconds for a subscriber on every topic before starting")
    a = ap.parse_args(argv)
    if not (a.rate > 0 and math.isfinite(a.rate)):
        ap.error("--rate must be a positive number")
    for opt, v in (("--delay", a.delay), ("--wait-for-subscribers", a.wait_for_subscribers)):
        if not 0 <= v <= MAX_WAIT:  # inf killed the player thread (time_t overflow) and published nothing
            ap.error(f"{opt} must be between 0 and {MAX_WAIT:g} s")
    return a


def main(args=None) -> int:
    """Console script ``hyst_bag_play``: :func:`hyst_common.node.run_node` with its own command line."""
    made: dict = {}

    def make(a: argparse.Namespace) -> PlayNode:
        node = PlayNode(list(read_raw(a.bag, a.topics)), a.rate, a.loop, a.delay, a.wait_for_subscribers)
        made.update(node=node, bag=a.bag)
        node.start()
        return node

    code = run_node(make, args, prog="hyst_bag_play", parse=_parse, executor="single", errors=(SimError,),
                    until=lambda n: n.done.is_set(), on_exit=lambda n, _: n.stop())
    if "node" in made:
        print(f"hyst_bag_play: published {made['node'].published} messages from {made['bag']}")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
