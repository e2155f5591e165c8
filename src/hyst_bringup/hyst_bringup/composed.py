"""hyst_loop_node: simulated stage, controller and reference node in one process, for 2 kHz loops.

Across processes every sample costs two DDS hops; in one process with
:class:`rclpy.experimental.EventsExecutor` (fallback: SingleThreadedExecutor) the loop keeps up at 2 kHz.
The executor is driven with ``spin_once`` so SIGINT/SIGTERM end it (``EventsExecutor.spin()`` ignores them).

In realtime mode the controller samples the reference node's trajectory in process at each state's time
(:meth:`ControllerNode.follow`, exact) and ``/stage/reference`` is published for observers (a recorder) at
``--reference-rate``: a reference message per sample cost the loop as much as the stage's own messages
(``hyst demo`` with its recorder on a slow 2-core machine, three runs each, alternating: 8 340–9 572 of 12 000
periods missed with the topic, 2 909–6 993 in process). Lockstep keeps the topic (its stamps are the stage's
time, not the reference node's clock).

Usage::

    hyst_loop_node [--seconds S] [--schedule dppc:3,dmrac:3,pid:3] [--summary-json] [--wait-subscribers N]
                   --ros-args -p rate:=2000.0 -p shape:=sine -p frequency:=10.0

In lockstep the schedule and ``--seconds`` count the stage's time (its steps over its rate), not the wall clock;
at its own end a lockstep loop waits (at most 30 s) until reliable subscribers such as a recorder have taken what
it published, since it outruns them on a loaded machine.

``--ros-args`` parameters reach all three nodes (``rate`` sets the sim, controller and reference rate alike);
``-p hyst_controller:algorithm:=dmrac`` targets one node. ``--schedule`` switches the controller's ``algorithm``
parameter through its own parameter callbacks, bumplessly, each entry lasting its seconds and until its algorithm
has tracked a sample (at most 3× its seconds: on a loaded machine start-up can take the first ones);
``--summary-json`` prints the per-algorithm tracking summary (RMSE/MAE in m) and loop counters as one JSON line at
exit.
"""
from __future__ import annotations

import argparse
import json
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from hyst_common.node import STARTUP_ERRORS
from hyst_common.startup import end_quiet_start
from hyst_common.stopping import StopGuard
from hyst_control.controller_node import ControllerNode
from hyst_control.controllers import parse_schedule
from hyst_control.errors import ControlError
from hyst_control.reference_node import ReferenceNode
from hyst_sim.sim_node import SimNode

__all__ = ["main"]


def _executor():
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    except ImportError:  # pragma: no cover - older rclpy
        return SingleThreadedExecutor()


def main(args=None) -> int:
    """Console script ``hyst_loop_node``."""
    end_quiet_start()  # the guard below takes the signals (the summary is still printed)
    argv = remove_ros_args(args=sys.argv if args is None else args)[1:]
    ap = argparse.ArgumentParser(prog="hyst_loop_node", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=None, help="stop after this many seconds")
    ap.add_argument("--schedule", default="", help="ALG:SECONDS,... switch algorithm on a timetable")
    ap.add_argument("--summary-json", action="store_true", help="print the tracking summary as JSON at exit")
    ap.add_argument("--reference-rate", type=float, default=200.0, metavar="HZ",
                    help="realtime: /stage/reference publication rate for observers (default %(default)s Hz; the "
                         "controller samples the trajectory in process at every state)")
    ap.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                    help="start only once /stage/state and /stage/command each have N subscribers (e.g. 2 = "
                         "the loop's own plus a recorder's), at most 30 s")
    opts = ap.parse_args(argv)
    try:
        schedule = parse_schedule(opts.schedule)
    except ControlError as err:
        print(f"hyst_loop_node: {err}", file=sys.stderr)
        return 2
    if not 1.0 <= opts.reference_rate <= 5000.0:
        print("hyst_loop_node: --reference-rate must be within [1, 5000] Hz", file=sys.stderr)
        return 2
    if opts.seconds is not None and not 0.0 < opts.seconds <= 86400.0:  # -1 ran 0 s, nan until a signal
        print("hyst_loop_node: --seconds must be within (0, 86400] s (leave it out to run until Ctrl-C)",
              file=sys.stderr)
        return 2
    if opts.wait_subscribers < 0:
        print("hyst_loop_node: --wait-subscribers must be 0 or more", file=sys.stderr)
        return 2

    # signals as every hyst node takes them (hyst_common.node.run_node): a flag the loop reads, not rclpy's
    # KeyboardInterrupt inside a callback (a '[FATAL] Exception in callback' on one Ctrl-C in 2 of 7 stops)
    guard = StopGuard("hyst_loop_node", install=threading.current_thread() is threading.main_thread())
    try:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RuntimeError as err:  # a bad --ros-args section
            print(f"hyst_loop_node: error: ROS arguments not understood: {err}", file=sys.stderr)
            return 2
        return _run(opts, schedule, guard)
    finally:
        guard.close(exiting=args is None)


def _run(opts: argparse.Namespace, schedule: list, guard: StopGuard) -> int:
    nodes: list = []
    ctl = None
    t_start = t_end = None
    try:
        try:  # a parameter out of its range, a missing params file: one line and exit 2, as the nodes alone
            for make in (SimNode, ControllerNode, ReferenceNode):
                nodes.append(make())
        except STARTUP_ERRORS as err:
            print(f"hyst_loop_node: error: {err}", file=sys.stderr)
            return 2
        sim, ctl, ref = nodes
        res = ref.set_parameters([Parameter("rate", value=float(opts.reference_rate))])[0]
        if not res.successful:
            raise ControlError(res.reason)
        lockstep = sim.get_parameter("mode").value == "lockstep"
        if not lockstep:
            ctl.follow(lambda t: ref.sample_at(int(round(t * 1e9)))[0])
        else:  # lockstep: the trajectory runs on the stage's time, not the wall clock (reproducible runs)
            ref.follow_clock()
            ctl.follow(_on_stage_time(ref))
        if opts.wait_subscribers > 0:  # e.g. a bag recorder: nothing runs (no timers) until it listens
            until = time.monotonic() + 30.0
            while time.monotonic() < until and rclpy.ok() and not guard.stopped and not (
                    ctl.count_subscribers("/stage/state") >= opts.wait_subscribers
                    and ctl.count_subscribers("/stage/command") >= opts.wait_subscribers):
                time.sleep(0.05)
        ex = _executor()
        for n in nodes:
            ex.add_node(n)
        guard.phase("spin")
        t_start = time.monotonic()
        clock = _clock(sim, t_start, lockstep)
        seg, seg_start = -1, 0.0
        while rclpy.ok() and not guard.stopped:
            now = clock()
            if schedule and (seg < 0 or _segment_done(ctl, schedule[seg], now - seg_start)):
                if seg + 1 == len(schedule):
                    if opts.seconds is None:
                        break
                else:
                    seg, seg_start = seg + 1, now
                    if ctl.get_parameter("algorithm").value != schedule[seg][0]:
                        res = ctl.set_parameters([Parameter("algorithm", value=schedule[seg][0])])[0]
                        if not res.successful:
                            raise ControlError(res.reason)
            if opts.seconds is not None and now >= opts.seconds:
                break
            ex.spin_once(timeout_sec=0.05)
        t_end = time.monotonic()
        # its own end, not a signal's (a user's Ctrl-C is not kept waiting for a stalled subscriber), in lockstep:
        # there the stage stops with the loop, while a realtime stage samples on and a wait only piled missed
        # periods onto the run's counts (4 000-6 000 in a 6 s demo against 150-350)
        if rclpy.ok() and not guard.stopped and lockstep:
            _wait_delivered(nodes, guard)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ControlError, ValueError) as err:
        print(f"hyst_loop_node: {err}", file=sys.stderr)
        return 2
    finally:
        guard.phase("exit")
        if opts.summary_json and ctl is not None:
            elapsed = ((t_end or time.monotonic()) - t_start) if t_start else 0.0
            sim_counts = dict(nodes[0].counts) if nodes else {}
            print(json.dumps({"tracking": ctl.tracking_summary(), "controller": ctl.counts,
                              "sim": sim_counts, "seconds": elapsed}), flush=True)
        guard.phase("teardown")
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown()
    return 0


def _on_stage_time(ref: ReferenceNode):
    """The controller's reference source in lockstep: the trajectory sampled at the stage's time, and published
    for observers at the reference node's rate on the same time (its own timer runs on the wall clock: a lockstep
    run followed a 4.7 Hz sine for a 10 Hz one, and two runs differed)."""
    last = [-(1 << 62)]

    def source(t: float) -> float:
        ns = int(round(t * 1e9))
        if ns - last[0] >= 1e9 / ref.rate:
            ref.publish_at(ns)
            last[0] = ns
        return ref.sample_at(ns)[0]
    return source


#: At most this long (s) at exit for a slower subscriber (a recorder) to take what the loop published.
DELIVERY_WAIT = 30.0


def _wait_delivered(nodes: list, guard: StopGuard) -> None:
    """Wait until every reliable subscriber has acknowledged what the nodes published, at most
    :data:`DELIVERY_WAIT` s in all: a lockstep loop outruns a recorder on a loaded machine, and the samples still in
    the publishers' queues went with the process (a 2 s ``hyst demo --lockstep`` bag held 427 of 4000 states)."""
    from rclpy.duration import Duration
    until = time.monotonic() + DELIVERY_WAIT
    for n in nodes:
        for pub in list(n.publishers):
            if time.monotonic() >= until or guard.stopped:
                return
            try:  # in slices of at most 0.5 s (a stop signal ends the wait), never negative (that waits for ever)
                while not pub.wait_for_all_acked(Duration(seconds=min(max(until - time.monotonic(), 1e-3), 0.5))):
                    if guard.stopped or time.monotonic() >= until:
                        return
            except Exception:  # noqa: BLE001 - a publisher already gone or a shut-down context: nothing to wait for
                pass


def _clock(sim: SimNode, t_start: float, lockstep: bool):
    """The schedule's clock: wall time in realtime; in lockstep the stage's own time (its steps over its rate), so
    a segment is the same number of samples on every machine (by wall time a loaded machine ran DPPC for 367-828
    of 2000 lockstep samples, and the figures moved with it)."""
    if not lockstep:
        return lambda: time.monotonic() - t_start
    rate = float(sim.get_parameter("rate").value)
    return lambda: sim.counts["samples"] / rate


#: A schedule segment runs at most this many times its duration while its algorithm has tracked no sample.
SEGMENT_STRETCH = 3.0


def _segment_done(ctl, segment: tuple[str, float], elapsed: float) -> bool:
    """A segment ends after its duration once its algorithm has tracked a sample — on a loaded machine the first
    seconds can go to start-up and the settling skip after a switch, and a wall-clock timetable then gave DPPC
    no tracked sample at all (``hyst demo`` beside CI: 0 of 119-265) — but never later than
    :data:`SEGMENT_STRETCH` times its duration."""
    alg, dur = segment
    if elapsed < dur:
        return False
    return ctl.tracking_summary().get(alg, {}).get("samples", 0) > 0 or elapsed >= SEGMENT_STRETCH * dur


if __name__ == "__main__":
    raise SystemExit(main())
