"""hyst_sim_node: the simulated stage on ROS topics, interchangeable with the driver (docs/ARCHITECTURE.md).

Publishes ``/stage/state`` (``sensor_msgs/JointState``: ``name=['stage']``, ``position[0]`` sensor reading in m,
``effort[0]`` applied voltage in V, ``header.stamp`` = sample time), subscribes ``/stage/command``
(``effort[0]`` commanded V, ``header.stamp`` = stamp of the state it answers), reports health (clipping, command
timeout, timing) on ``/diagnostics`` and in a throttled log. The plant's internals — true position, effect
names and strengths loaded from ``scenario_file`` — never appear on a topic, in a log or in a parameter.

Modes
-----
``realtime``
    A sampling thread takes one sample per period ``1/rate`` with the latest command, stamped with the node
    clock; the executor thread only handles commands and parameters. (A thread, not an rclpy timer: measured
    here, a SingleThreadedExecutor timer does not hold 1 kHz on a loaded 2-core machine and EventsExecutor
    timers do not fire at all.) When it falls behind by more than a period it does not publish the missed
    samples (no burst) but advances the plant over them at the held voltage, as a real stage keeps moving, and
    counts them (``missed_periods`` on /diagnostics); ``hyst fit --gaps bridge`` spans such gaps exactly. No
    command for ``command_timeout`` s → the voltage ramps to ``v_safe`` at ``safe_ramp_rate`` V/s. The first
    sample is taken once ``/stage/state`` has ``wait_for_subscribers`` subscribers (default 1), as in lockstep.
``lockstep`` (deterministic tests)
    Sample 0 (the stage at rest at ``v_safe``) is published, stamped 0 s, as soon as ``/stage/state`` has
    ``wait_for_subscribers`` subscribers (default 1; 2 with a recorder: ``hyst_bag_record`` started first then
    never misses the start) and ``/stage/command`` a publisher, and re-published with the *same* stamp every 0.5 s
    until it is answered. Each command whose ``header.stamp`` equals the latest state's stamp takes exactly one sample
    and publishes state ``k+1`` stamped ``(k+1)/rate`` s; commands with any other stamp (duplicates, answers to
    a repeated state) are dropped and counted as stale. Same parameters and seed → same data, bit for bit.
    A reliable subscriber slower than the loop (a recorder on a busy machine) slows the run instead of losing
    samples (keep-all history; the waits are counted as ``waits_for_slow_subscribers`` on /diagnostics).

Health on ``/diagnostics`` (every second): ``hyst_sim: stage`` — the stage on its end stop (an input the model
cannot follow, a diverging model) is an ERROR, never a number; clipping, timeouts, missed periods a WARN.
``hyst_sim: timing`` — missed realtime periods with their share of the second (a WARN, an ERROR above 10 %). Parameter
sets are all or nothing: :meth:`SimNode.set_parameters` and the node's ``set_parameters`` service (rclpy's sets each
parameter alone) validate the whole resulting configuration and apply every parameter or none.

Length (~450 lines): one node class; its settings (``sim_settings.py``) and plant (``plant.py``) are apart, and
what remains — the two sampling modes, the command path, diagnostics — shares the node's state and its locks.
"""
from __future__ import annotations

import math
import threading
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import (ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy._rclpy_pybind11 import RCLError  # what a failed publish raises; rclpy exports it nowhere public
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from hyst_common.limits import beyond_span
from hyst_common.node import (KEEP_ALL_RELIABLE, AtomicParametersNode, diagnostic_array, diagnostic_status, fp_range,
                              int_range, run_node)
from hyst_common.runtime import RT_PRIORITY_MAX, set_realtime

from .errors import SimError
from .plant import Plant
from hyst_common.profiles import CUSTOM_V_MAX, PEA, V_SPAN, custom_slew, get_profile, rest_voltage
from .sim_settings import SimSettings, plant_config
from .truth_effects import EFFECT_NAMES, Effects

__all__ = ["SimNode", "SimSettings", "plant_config", "main"]

_DIAG_PERIOD = 1.0      # s between /diagnostics messages
_ANNOUNCE_PERIOD = 0.5  # s between repeats of the unanswered lockstep sample 0
_MISSED_ERROR = 0.10    # share of missed realtime periods in a second that is an ERROR, not a WARN


class SimNode(AtomicParametersNode):
    """The simulated stage node; see the module docstring."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_sim", **kwargs)  # parameter sets all or nothing (AtomicParametersNode)
        self._declare_parameters()
        self._settings = self._read_settings()
        try:
            self._settings.validate()
            pc = plant_config(self._settings)
            self._plant = Plant(pc)
        except (SimError, ValueError) as err:
            raise SimError(f"invalid start-up parameters: {err}") from err
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._after_set)

        # realtime: deep history, so a reliable subscriber slow for a moment (a recorder) loses nothing, and the
        # sampler never waits for anyone. Lockstep: keep-all, so a reliable subscriber slower than the loop (a
        # recorder on a loaded machine) slows the run down instead of losing samples (measured: keep-last 1000
        # lost 160 stretches of 20000 fast samples to a slow reader; keep-all lost none)
        if self._settings.mode == "lockstep":
            qos = KEEP_ALL_RELIABLE
        else:
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self._pub = self.create_publisher(JointState, "/stage/state", qos)
        self._wait_n = int(self.get_parameter("wait_for_subscribers").value)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "/stage/command", self._on_command, 10)
        # (last commanded voltage V, monotonic arrival time), one object: atomic
        self._cmd: tuple[float, float] | None = None
        self._k = 0                      # samples taken
        self._stamp_ns = 0               # lockstep clock (ns)
        self._last_msg: JointState | None = None
        self._answered = False
        self._counts = dict.fromkeys(("samples", "clip_range", "clip_slew", "nonfinite", "rejected", "bad_messages",
                                      "stale", "timeouts", "late_ticks", "end_stop", "waits"), 0)
        self._period_counts = dict(self._counts)
        self._timed_out = False
        self._lock = threading.Lock()    # the plant is stepped by the sampler and reconfigured by the executor
        self._stop = threading.Event()
        self._timer = None
        self._sampler = None
        # before the sampler thread starts, which inherits it
        self.scheduling = set_realtime(int(self.get_parameter("rt_priority").value))
        if self.get_parameter("rt_priority").value and self.scheduling.policy != "fifo":
            self.get_logger().warning(f"{self.scheduling.note}; running with normal scheduling")
        if self._settings.mode == "realtime":
            self._sampler = threading.Thread(target=self._sample_loop, name="hyst_sim_sampler", daemon=True)
            self._sampler.start()
        else:
            self._timer = self.create_timer(0.01, self._announce)
            self._announce_at = 0.0
        self.create_timer(_DIAG_PERIOD, self._publish_diagnostics)
        self.get_logger().info(
            f"simulated stage: profile {self._settings.profile}, {self._settings.rate:g} Hz, mode "
            f"{self._settings.mode}, model "
            f"{'from ' + self._settings.params_file if self._settings.params_file else 'embedded default'}"
            f"{', scenario loaded' if self._settings.scenario_file else ''}, scheduling {self.scheduling}")

    # Parameters ---------------------------------------------------------------------------------------------
    def _declare_parameters(self) -> None:
        d = self.declare_parameter
        d("profile", "pea", ParameterDescriptor(
            description="actuator profile: pea (0-150 V) | gma (+-5 V) | custom (another stage: needs params_file, "
                        "v_min and v_max)", additional_constraints="one of: pea, gma, custom"))
        name = self.get_parameter("profile").value
        custom = name == "custom"
        prof = PEA if custom else get_profile(name)  # custom: the rig's sensor; no default range
        box = (-CUSTOM_V_MAX, CUSTOM_V_MAX) if custom else V_SPAN
        d("rate", 1000.0, ParameterDescriptor(description="sample rate (Hz); 2000 needs a single process",
                                              floating_point_range=fp_range(1.0, 5000.0)))
        d("v_min", 0.0 if custom else prof.v_min, ParameterDescriptor(
            description="lowest voltage applied (V), inside the profile", floating_point_range=fp_range(*box)))
        d("v_max", 0.0 if custom else prof.v_max, ParameterDescriptor(
            description="highest voltage applied (V), inside the profile", floating_point_range=fp_range(*box)))
        lo, hi = (float(self.get_parameter(n).value) for n in ("v_min", "v_max"))
        slew = custom_slew(lo, hi) if custom else prof.slew_max
        d("slew_max", slew, ParameterDescriptor(description="amplifier slew limit (V/s)",
                                                floating_point_range=fp_range(1e-3, 1e8)))
        d("command_timeout", 0.2, ParameterDescriptor(
            description="no command for this long (s) -> ramp to v_safe (realtime mode)",
            floating_point_range=fp_range(1e-3, 3600.0)))
        d("v_safe", rest_voltage(lo, hi) if custom else prof.v_safe, ParameterDescriptor(
            description="voltage at start and after a timeout (V)", floating_point_range=fp_range(*box)))
        d("safe_ramp_rate", 100.0, ParameterDescriptor(description="ramp rate towards v_safe after a timeout (V/s)",
                                                       floating_point_range=fp_range(1e-3, 1e8)))
        d("frame_id", "stage", ParameterDescriptor(description="header.frame_id of /stage/state"))
        d("mode", "realtime", ParameterDescriptor(
            description="realtime | lockstep (one sample per answered state; deterministic)", read_only=True,
            additional_constraints="one of: realtime, lockstep; fixed at start"))
        d("wait_for_subscribers", 1, ParameterDescriptor(
            description="publish the first sample only once /stage/state has this many subscribers (controller "
                        "+ recorder = 2), so no subscriber misses the start (both modes)", read_only=True,
            integer_range=int_range(1, 100)))
        d("params_file", "", ParameterDescriptor(description="MBW params file ('' = embedded default stage)"))
        d("scenario_file", "", ParameterDescriptor(
            description="hidden-effects scenario file ('' = none); its contents are never reported"))
        d("seed", 0, ParameterDescriptor(description="seed of sensor noise and drift (set at start: a change at run "
                                                     "time was accepted and did nothing)", read_only=True,
                                         integer_range=int_range(0, 2**31 - 1)))
        d("rt_priority", 0, ParameterDescriptor(
            description="SCHED_FIFO priority of the node's threads, as the driver's (0 = normal scheduling; "
                        "applies at start; see hyst_common.runtime)", read_only=True,
            integer_range=int_range(0, RT_PRIORITY_MAX)))
        for name in EFFECT_NAMES:
            spec = Effects.spec(name)
            default = {"noise": prof.sensor_noise, "quantization": prof.sensor_resolution}.get(name, 0.0)
            desc = f"{spec.doc} [{spec.unit}]" if spec.unit else spec.doc
            if spec.integer:
                d(f"effects.{name}", int(default), ParameterDescriptor(
                    description=desc, integer_range=int_range(int(spec.lower), int(spec.upper))))
            else:
                d(f"effects.{name}", float(default), ParameterDescriptor(
                    description=desc, floating_point_range=fp_range(spec.lower, spec.upper)))

    def _read_settings(self, changes: dict | None = None) -> SimSettings:
        def get(name):
            if changes and name in changes:
                return changes[name]
            return self.get_parameter(name).value

        return SimSettings(
            rate=float(get("rate")), profile=str(get("profile")), v_min=float(get("v_min")),
            v_max=float(get("v_max")), slew_max=float(get("slew_max")), command_timeout=float(get("command_timeout")),
            v_safe=float(get("v_safe")), safe_ramp_rate=float(get("safe_ramp_rate")), frame_id=str(get("frame_id")),
            mode=str(get("mode")), params_file=str(get("params_file")), scenario_file=str(get("scenario_file")),
            seed=int(get("seed")), effects=tuple((n, get(f"effects.{n}")) for n in EFFECT_NAMES))

    def _on_set(self, params) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        for p in params:
            if p.name.startswith("effects.") and p.type_ == ParameterType.PARAMETER_DOUBLE \
                    and not math.isfinite(p.value):
                return SetParametersResult(successful=False, reason=f"{p.name} must be finite")
        try:
            s = self._read_settings(changes)
            s.validate()
            Plant(plant_config(s))  # builds and checks everything the swap will need
        except (SimError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _after_set(self, params) -> None:
        new = self._read_settings()
        with self._lock:
            self._plant.reconfigure(plant_config(new))
            self._settings = new
        named = [p.name for p in params if not p.name.startswith(("scenario_file",))]
        self.get_logger().info("parameters applied: " + (", ".join(named) if named else "the scenario (not shown)"))

    # Commands and samples -----------------------------------------------------------------------------------
    def _on_command(self, msg: JointState) -> None:
        if not msg.effort:
            self._count("bad_messages")
            self.get_logger().warning("command without effort[0] (V) ignored", throttle_duration_sec=1.0)
            return
        v = float(msg.effort[0])
        if self._settings.mode == "realtime":
            self._cmd = (v, time.monotonic())
            return
        last = self._last_msg
        if last is None or (msg.header.stamp.sec, msg.header.stamp.nanosec) != (last.header.stamp.sec,
                                                                                 last.header.stamp.nanosec):
            self._count("stale")
            return
        self._answered = True
        self._stamp_ns += int(round(1e9 * self._settings.dt))
        self._sample(v, _time_from_ns(self._stamp_ns))

    def _sample(self, v_cmd: float, stamp: Time) -> None:
        with self._lock:
            s = self._settings
            huge = math.isfinite(v_cmd) and beyond_span(v_cmd, s.v_min, s.v_max)  # NaN: the plant holds it
            if huge:  # as the driver's limiter: a corrupt or unit-confused command holds, it is not full scale
                v_huge, v_cmd = v_cmd, self._plant.u_applied
            try:
                r = self._plant.step(v_cmd)
            except SimError as err:  # a diverging user model: say so once per second, keep the node alive
                self.get_logger().error(str(err), throttle_duration_sec=1.0)
                self._plant.reset()
                return
        self._k += 1
        self._count("samples")
        if huge:
            self._count("rejected")
            self.get_logger().warning(
                f"command {v_huge:.6g} V rejected, {r.u_applied:.6g} V held: more than the range's span outside "
                f"[{s.v_min:g}, {s.v_max:g}] V (a corrupt or unit-confused command; the driver rejects it too)",
                throttle_duration_sec=1.0)
        if r.clipped:
            if not math.isfinite(v_cmd):
                self._count("nonfinite")
            elif v_cmd < s.v_min or v_cmd > s.v_max:
                self._count("clip_range")
            else:
                self._count("clip_slew")
            self.get_logger().warning(
                f"command {v_cmd:.6g} V clipped to {r.u_applied:.6g} V (range [{s.v_min:g}, {s.v_max:g}] V, slew "
                f"{s.slew_max:g} V/s)", throttle_duration_sec=1.0)
        if r.at_stop:
            self._count("end_stop")
            self.get_logger().error(
                f"the stage is on its end stop (y = {r.y:.6g} m, stroke {self._plant.stroke_range[0]:.3g}–"
                f"{self._plant.stroke_range[1]:.3g} m): the input drives the model outside its travel",
                throttle_duration_sec=1.0)
        msg = JointState()
        msg.header.stamp = stamp
        msg.header.frame_id = s.frame_id
        msg.name = ["stage"]
        msg.position = [r.y]
        msg.effort = [r.u_applied]
        self._last_msg = msg
        self._publish(msg)

    def _publish(self, msg: JointState) -> None:
        """Publish a state; in lockstep, wait (and say so) while a reliable subscriber cannot take it yet.

        A keep-all writer blocks for up to 100 ms when a reader has not taken its backlog, then fails; lockstep
        retries until the sample is out (or the node stops), so every subscriber gets every sample.
        """
        while True:
            try:
                self._pub.publish(msg)
                return
            except RCLError:
                if self._settings.mode != "lockstep" or self._stop.is_set() or not self.context.ok():
                    raise
                self._count("waits")
                self.get_logger().warning("a subscriber of /stage/state is not keeping up: lockstep waits for it",
                                          throttle_duration_sec=5.0)

    def _sample_loop(self) -> None:
        """Realtime mode: one sample per period on a fixed schedule; skip (and count) periods when behind."""
        # the first sample waits for wait_for_subscribers matched subscribers (a recorder then has the run's
        # start); the stage rests at v_safe meanwhile, so nothing happens that a subscriber could miss
        while self._pub.get_subscription_count() < self._wait_n:
            if self._stop.wait(0.01):
                return
        due = time.monotonic()
        # each sample is stamped with its scheduled time on the ROS clock, not with the moment the thread got to
        # it: wall-clock stamps jittered by a late thread read as missed periods (a loaded machine's realtime bag
        # of an effect-free stage fitted at 76 nm for 2 nm in lockstep), while real misses stay whole periods
        ros0, mono0 = self.get_clock().now().nanoseconds, due
        while not self._stop.is_set():
            dt = self._settings.dt
            due += dt
            wait = due - time.monotonic()
            if wait > 0:
                if self._stop.wait(wait):
                    return
            elif wait < -dt:
                missed = int(-wait / dt)
                self._count("late_ticks", missed)
                due += missed * dt
                self.get_logger().warning(f"sampler behind: {missed} period(s) missed (plant advanced at the held "
                                          "voltage, not published)", throttle_duration_sec=5.0)
                self._hold(missed)
            try:
                self._tick(_time_from_ns(ros0 + int(round((due - mono0) * 1e9))))
            except Exception as err:  # noqa: BLE001 - never let the sampler die silently
                if not self.context.ok():  # shutting down (SIGINT/SIGTERM): stop quietly
                    return
                self.get_logger().error(f"sampling failed: {err}", throttle_duration_sec=1.0)

    def destroy_node(self) -> None:
        self._stop.set()
        if self._sampler is not None and self._sampler.is_alive():
            self._sampler.join(timeout=2.0)
        super().destroy_node()

    def _hold(self, periods: int) -> None:
        """Advance the plant over periods the sampler missed, at the applied voltage, without publishing.

        A real stage keeps moving while its sampler is late and the DAC holds the last voltage; skipping the
        plant steps instead would make the stage's own time stand still across the gap. A bag then shows a gap
        over which the held input is exactly what the stage saw, so ``hyst fit --gaps bridge`` can span it.
        Capped at 10 s of steps (a process stopped for longer has lost the experiment anyway).
        """
        with self._lock:
            u = self._plant.u_applied
            for _ in range(min(periods, int(10.0 * self._settings.rate))):
                try:
                    self._plant.step(u)
                except SimError as err:
                    self.get_logger().error(str(err), throttle_duration_sec=1.0)
                    self._plant.reset()
                    return

    def _tick(self, stamp: Time) -> None:
        s = self._settings
        now = time.monotonic()
        cmd = self._cmd
        if cmd is not None and now - cmd[1] <= s.command_timeout:
            v = cmd[0]
            self._timed_out = False
        else:
            if cmd is not None and not self._timed_out:
                self._timed_out = True
                self._count("timeouts")
                self.get_logger().warning(f"no command for {s.command_timeout:g} s: ramping to v_safe = "
                                          f"{s.v_safe:g} V")
            u = self._plant.u_applied
            step = s.safe_ramp_rate * s.dt
            v = min(max(s.v_safe, u - step), u + step)
        self._sample(v, stamp)

    def _announce(self) -> None:
        """Lockstep: publish sample 0 once someone listens and commands, repeat it until it is answered."""
        if self._answered:
            if self._timer is not None:  # it is: this is its callback
                self.destroy_timer(self._timer)
            self._timer = None
            return
        if self._pub.get_subscription_count() < self._wait_n or self.count_publishers("/stage/command") == 0:
            return
        now = time.monotonic()
        if now < self._announce_at:
            return
        self._announce_at = now + _ANNOUNCE_PERIOD
        if self._last_msg is None:
            self._sample(self._settings.v_safe, _time_from_ns(0))
        else:
            self._publish(self._last_msg)

    # Health ---------------------------------------------------------------------------------------------------
    def _count(self, key: str, n: int = 1) -> None:
        self._counts[key] += n

    def _publish_diagnostics(self) -> None:
        s, c = self._settings, self._counts
        d = {k: c[k] - self._period_counts[k] for k in c}
        self._period_counts = dict(c)
        problems = []
        if d["clip_range"] or d["clip_slew"] or d["nonfinite"]:
            problems.append(f"clipping ({d['clip_range']} range, {d['clip_slew']} slew, {d['nonfinite']} "
                            f"non-finite in {_DIAG_PERIOD:g} s)")
        if self._timed_out:
            problems.append(f"command timeout: ramping to v_safe = {s.v_safe:g} V")
        if d["late_ticks"]:
            problems.append(f"{d['late_ticks']} missed periods")
        if d["bad_messages"]:
            problems.append(f"{d['bad_messages']} malformed commands")
        if d["rejected"]:
            problems.append(f"{d['rejected']} commands rejected (beyond the range by more than its span)")
        if d["end_stop"]:
            problems.insert(0, f"FAULT: stage on its end stop in {d['end_stop']} samples (the input drives the "
                               "model outside its travel)")
        level = DiagnosticStatus.ERROR if d["end_stop"] else (
            DiagnosticStatus.WARN if problems else DiagnosticStatus.OK)
        message = "; ".join(problems) if problems else (
            "waiting for commands" if self._cmd is None and self._k <= 1 else "ok")
        vals = {"mode": s.mode, "rate_hz": f"{s.rate:g}", "achieved_rate_hz": f"{d['samples'] / _DIAG_PERIOD:g}",
                "samples": c["samples"], "v_applied": f"{self._plant.u_applied:.6g}",
                "clipped_range": c["clip_range"], "clipped_slew": c["clip_slew"],
                "nonfinite_commands": c["nonfinite"], "rejected_commands": c["rejected"],
                "malformed_commands": c["bad_messages"],
                "stale_commands": c["stale"], "timeouts": c["timeouts"], "missed_periods": c["late_ticks"],
                "end_stop_samples": c["end_stop"], "waits_for_slow_subscribers": c["waits"]}
        st = diagnostic_status("hyst_sim: stage", f"sim:{s.profile}", level, message, vals)
        self._diag_pub.publish(diagnostic_array(self, [st, self._timing_status(d)]))

    def _timing_status(self, d: dict) -> DiagnosticStatus:
        """The sampler's timing on its own status, so a late sampler does not mask the stage's level."""
        share = d["late_ticks"] / max(1, d["late_ticks"] + d["samples"])
        level = DiagnosticStatus.ERROR if share > _MISSED_ERROR else (
            DiagnosticStatus.WARN if d["late_ticks"] else DiagnosticStatus.OK)
        message = (f"{d['late_ticks']} missed periods ({100 * share:.0f} % of the last {_DIAG_PERIOD:g} s)"
                   if d["late_ticks"] else "no missed periods")
        return diagnostic_status("hyst_sim: timing", f"sim:{self._settings.profile}", level, message, {
            "missed_periods": self._counts["late_ticks"], "missed_share": f"{share:.3f}",
            "achieved_rate_hz": f"{d['samples'] / _DIAG_PERIOD:g}"})

    @property
    def counts(self) -> dict:
        """Cumulative health counters (samples, clip_range, clip_slew, nonfinite, stale, timeouts...)."""
        return dict(self._counts)


def usage() -> str:
    """Help text: the module description and every parameter with its range (from the one declaration table)."""
    lines = ["usage: hyst_sim_node [--ros-args -p NAME:=VALUE ...]", "", __doc__.split("\n\nModes")[0].strip(), "",
             "parameters (shared with the driver unless marked sim):",
             "  rate [Hz] 1000 (1..5000)   profile pea|gma|custom (sim: another stage, with params_file, v_min,",
             "  v_max)   v_min, v_max, v_safe [V] (profile defaults)",
             "  slew_max [V/s]   command_timeout [s] 0.2   safe_ramp_rate [V/s] 100 (sim)   frame_id 'stage'",
             "  mode realtime|lockstep (sim)   wait_for_subscribers (sim, lockstep) 1   params_file (sim)",
             "  scenario_file (sim, hidden)   seed (sim)",
             "effects (sim; 0 = off):"]
    for name in EFFECT_NAMES:
        spec = Effects.spec(name)
        lines.append(f"  effects.{name:<13} {spec.doc} [{spec.unit or '-'}], range {spec.lower:g}..{spec.upper:g}")
    return "\n".join(lines)


def _time_from_ns(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def main(args=None) -> int:
    """Console script ``hyst_sim_node`` (``--ros-args -p rate:=2000.0 -p mode:=lockstep ...``)."""
    return run_node(SimNode, args, prog="hyst_sim_node", usage=usage(), errors=(SimError,), executor="single")


if __name__ == "__main__":
    raise SystemExit(main())
