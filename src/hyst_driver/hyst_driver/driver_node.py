"""hyst_driver_node: the real stage behind the same topics and parameters as the sim.

Publishes ``/stage/state`` (JointState: ``position[0]`` m, ``effort[0]`` applied V, ``header.stamp`` = sample
time: the device's sample clock mapped onto the node clock, or the arrival time for protocols without one) and
``/diagnostics`` (link state, bad frames, device errors, timeouts, reconnects, clipping, watchdog, loop latency);
subscribes ``/stage/command`` (``effort[0]`` V; ``header.stamp`` = the state it answers). All serial work
happens in one I/O thread (:class:`hyst_driver.transport.DeviceLink`): commands wake it at once, samples are
published from it as they arrive, a lost port is reopened with backoff. Voltages leave only through the limiter
(:mod:`hyst_driver.safety`); when commands stop for ``command_timeout``, and on shutdown, the output ramps to
``v_safe`` at ``safe_ramp_rate``.
"""
from __future__ import annotations

import math
import sys
import threading
from collections import deque
from dataclasses import dataclass, replace

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.parameter import Parameter
from rclpy.time import Time
from sensor_msgs.msg import JointState

from hyst_common.errors import ConfigError as HystConfigError
from hyst_common.node import AtomicParametersNode, diagnostic_array, diagnostic_status, fp_range, int_range, run_node
from hyst_common.profiles import CUSTOM_V_MAX, GMA, PEA, Profile, check_range, custom_slew, get_profile, rest_voltage
from hyst_common.runtime import RT_PRIORITY_MAX, set_realtime

from .adapter import PROTOCOLS, make_adapter
from .errors import ConfigError, DriverError
from .safety import Limits
from .transport import DeviceLink, LinkHealth, SerialTransport

__all__ = ["DriverConfig", "DriverNode", "main"]


@dataclass(frozen=True)
class DriverConfig:
    """Validated parameters of the driver node (swapped whole on every accepted change)."""

    port: str
    baud: int
    protocol: str
    rate: float
    profile: str
    counts_to_m: float
    v_min: float
    v_max: float
    slew_max: float
    command_timeout: float
    v_safe: float
    safe_ramp_rate: float
    link_timeout: float
    frame_id: str
    rt_priority: int = 0

    def validate(self) -> "DriverConfig":
        """Cross-parameter checks; raises :class:`ConfigError` with a reason."""
        if not self.port:
            raise ConfigError("parameter 'port' is empty: give the device path, e.g. -p port:=/dev/ttyACM0 "
                              "(without hardware: run hyst_emulator and use the path it prints)")
        if self.protocol not in PROTOCOLS:
            raise ConfigError(f"protocol {self.protocol!r} unknown; choose one of {', '.join(PROTOCOLS)}")
        try:
            check_range(self.profile, self.v_min, self.v_max, self.slew_max)
        except HystConfigError as err:  # hyst_common's: the driver's own is raised
            raise ConfigError(str(err)) from err
        lim = self.limits()
        if lim.slew_max * lim.dt_max < 1e-6:
            raise ConfigError(f"slew_max {self.slew_max} V/s moves less than 1 uV per sample at {self.rate} Hz")
        if self.link_timeout <= 5.0 / self.rate:
            raise ConfigError(f"link_timeout {self.link_timeout} s must exceed 5 samples ({5.0 / self.rate} s)")
        return self

    def limits(self) -> Limits:
        return Limits(self.v_min, self.v_max, self.slew_max, self.v_safe, dt_max=1.0 / self.rate,
                      safe_ramp_rate=self.safe_ramp_rate)


def param_table(prof: Profile | None, v_range: tuple[float, float] = (0.0, 0.0)
                ) -> list[tuple[str, object, tuple | None, str]]:
    """``(name, default, range, description)`` of every parameter but ``profile``: the one table behind the
    declarations and ``--help``. Limits default to, and are ranged by, the profile (:mod:`hyst_common.profiles`);
    ``prof`` None is ``profile custom``: the limits are ranged by ±:data:`CUSTOM_V_MAX` and have no default range
    (``v_range``, the user's ``v_min``/``v_max`` when given, sets the slew and rest defaults), the sensor is the
    rig's (PEA's)."""
    if prof is None:
        lo, hi = -CUSTOM_V_MAX, CUSTOM_V_MAX
        dlo, dhi = v_range
        slew, safe, res = custom_slew(dlo, dhi), rest_voltage(dlo, dhi), PEA.sensor_resolution
    else:
        lo, hi = dlo, dhi = prof.v_min, prof.v_max
        slew, safe, res = prof.slew_max, prof.v_safe, prof.sensor_resolution
    return [
        ("port", "", None, "serial device or pty path (a stable /dev/serial/by-id/... link survives replugs)"),
        ("baud", 921600, (1200, 4000000), "UART baud rate (ignored by USB-CDC and ptys)"),
        ("protocol", "ascii", None, "device protocol: ascii (HDB/1, streamed, CRC-8) | gcs (GCS-like, polled)"),
        ("rate", 1000.0, (1.0, 2000.0), "sample rate, Hz (HDB/1 streams at the nearest integer)"),
        ("counts_to_m", res, (1e-12, 1e-3), "metres per sensor count (ascii; gcs reports um)"),
        ("v_min", dlo, (lo, hi), "lowest voltage ever sent, V"),
        ("v_max", dhi, (lo, hi), "highest voltage ever sent, V"),
        ("slew_max", slew, (1e-3, 1e9), "largest voltage rate ever sent, V/s"),
        ("command_timeout", 0.2, (1e-3, 3600.0), "no command for this long (s): ramp to v_safe"),
        ("v_safe", safe, (lo, hi), "voltage ramped to when commands stop and on shutdown, V"),
        ("safe_ramp_rate", 100.0, (1e-3, 1e9), "rate of the ramps to v_safe, V/s (never above slew_max)"),
        ("link_timeout", 0.5, (0.005, 60.0), "no sample for this long (s): close the port and reconnect"),
        ("frame_id", "stage", None, "header.frame_id of /stage/state"),
        ("rt_priority", 0, (0, RT_PRIORITY_MAX), "SCHED_FIFO priority of the I/O and executor threads "
         "(0 = normal scheduling; needs CAP_SYS_NICE or an rtprio limit; see hyst_common.runtime)"),
    ]


def usage() -> str:
    """``--help`` text: what the node does and every parameter with default and range (PEA; GMA differs)."""

    lines = ["usage: hyst_driver_node --ros-args -p port:=PATH [-p NAME:=VALUE ...]", "",
             __doc__.strip(), "", "parameters (defaults for profile pea; gma: v_min -5, v_max 5, v_safe 0, "
             f"slew_max {GMA.slew_max:g}; custom: v_min and v_max required, within +-{CUSTOM_V_MAX:g} V, slew_max a "
             "full swing in 1 ms, v_safe 0 V or the range end nearer it):",
             "  profile          pea | gma | custom (read-only)"]
    for name, default, rng, text in param_table(PEA):
        r = f" [{rng[0]:g} .. {rng[1]:g}]" if rng else ""
        lines.append(f"  {name:<16} {default!r}{r}  {text}")
    lines += ["", "without hardware: hyst_emulator prints a port path to use; protocols: see "
              "hyst_driver.protocol_ascii / protocol_gcs"]
    return "\n".join(lines)


class DriverNode(AtomicParametersNode):
    """Serial driver for the PEA/GMA amplifier and displacement sensor (see module docstring)."""

    #: Parameters that need a new connection; changing them at run time is refused with a reason.
    RESTART = ("port", "baud", "protocol", "rate", "profile", "counts_to_m", "link_timeout", "rt_priority")

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_driver", **kwargs)
        self.declare_parameter("profile", "pea", ParameterDescriptor(
            description="actuator profile: pea (0..150 V) | gma (+-5 V) | custom (another amplifier: set v_min and "
                        "v_max); sets the limits' defaults and ranges", read_only=True,
            additional_constraints="one of: pea, gma, custom"))
        name = str(self.get_parameter("profile").value).strip().lower()
        prof = None if name == "custom" else get_profile(name)  # ConfigError for a bad name → main()
        given = (self._override("v_min"), self._override("v_max"))
        for name, default, rng, text in param_table(prof, given):
            desc = ParameterDescriptor(description=text)
            if isinstance(default, (int, float)):
                if rng is None:  # every number in the table has its range
                    raise ConfigError(f"parameter {name}: a number without a range")
                if isinstance(default, int):
                    desc.integer_range = int_range(rng[0], rng[1])
                else:
                    desc.floating_point_range = fp_range(*rng)
            self.declare_parameter(name, default, desc)
        self.cfg = self._read_config({}).validate()
        self.add_on_set_parameters_callback(self._on_set)

        c = self.cfg
        # read-backs outside the amplifier's range are corrupt lines; a custom stage's amplifier range is not known,
        # only the command window, which may widen at run time or not hold where the device sits at start (taking
        # it as the plausible range locked the link out: no handshake, so no ramp down either)
        lo, hi = (prof.v_min, prof.v_max) if prof else (-CUSTOM_V_MAX, CUSTOM_V_MAX)
        adapter = make_adapter(c.protocol, c.counts_to_m, (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)))
        self.link = DeviceLink(SerialTransport(c.port, c.baud), adapter, c.limits(), round(c.rate),
                               command_timeout=c.command_timeout, link_timeout=c.link_timeout)
        self.pub_state = self.create_publisher(JointState, "/stage/state", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "/stage/command", self._on_command, 10)
        self.create_timer(1.0, self._publish_diagnostics)
        self.bad_commands = 0
        self.io_errors = 0
        self._latency: deque[int] = deque(maxlen=2000)  # ns, sample time -> command arrival
        self._stop = threading.Event()
        # before any loop thread starts: the I/O thread (and the executor thread main() starts) inherit it
        self.scheduling = set_realtime(c.rt_priority)
        if c.rt_priority and self.scheduling.policy != "fifo":
            self.get_logger().warning(f"rt_priority {c.rt_priority}: {self.scheduling.note}; running with normal "
                                      "scheduling (the 1 kHz loop may miss deadlines under load)")
        self._io = threading.Thread(target=self._io_loop, name="hyst_driver_io", daemon=True)
        self._io.start()
        self.get_logger().info(f"{c.protocol} device on {c.port}, profile {c.profile}, {c.rate:g} Hz, "
                               f"limits [{c.v_min}, {c.v_max}] V, {c.slew_max:g} V/s, safe {c.v_safe} V, "
                               f"scheduling {self.scheduling}")

    # ------------------------------------------------------------ parameters
    def _override(self, name: str) -> float:
        """The start-up value given for ``name`` (0.0 when none or not a number): ``profile custom`` takes its slew
        and rest defaults from the range the user gives."""
        p = self._parameter_overrides.get(name)
        try:
            return float(p.value) if p is not None else 0.0
        except (TypeError, ValueError):
            return 0.0

    def _read_config(self, changes: dict) -> DriverConfig:
        names = DriverConfig.__dataclass_fields__
        vals = {n: changes.get(n, self.get_parameter(n).value) for n in names}
        vals["baud"], vals["rate"] = int(vals["baud"]), float(vals["rate"])
        return DriverConfig(**vals)

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        fixed = [n for n in changes if n in self.RESTART and changes[n] != getattr(self.cfg, n)]
        if fixed:
            return SetParametersResult(successful=False,
                                       reason=f"{', '.join(fixed)} cannot change while running: restart the node")
        try:
            cfg = replace(self.cfg, **{k: v for k, v in changes.items() if k in DriverConfig.__dataclass_fields__})
            cfg.validate()
        except (ConfigError, TypeError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        self.cfg = cfg
        self.link.set_limits(cfg.limits(), cfg.command_timeout)
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------ data path
    def _on_command(self, msg: JointState) -> None:
        if not msg.effort:
            self.bad_commands += 1  # a malformed message is counted, never fatal; the watchdog still runs
            self.get_logger().warning("command without effort[0] ignored", throttle_duration_sec=1.0)
            return
        v = float(msg.effort[0])
        if not math.isfinite(v):  # the limiter refuses it too; say so here, where the user looks
            self.get_logger().warning(f"command {v} V refused: the output holds the last good one",
                                      throttle_duration_sec=1.0)
        self.link.command(v)
        st = msg.header.stamp
        if st.sec or st.nanosec:  # answers a state sample: sample time -> command arrival is the loop latency
            self._latency.append(self.get_clock().now().nanoseconds - (st.sec * 1_000_000_000 + st.nanosec))

    def _io_loop(self) -> None:
        link, clock = self.link, self.get_clock()
        while not self._stop.is_set():
            try:
                link.wait(link.next_deadline() - link.clock())
                readings = link.service()
                if readings:
                    self._publish_states(readings, clock)
            except Exception as err:  # noqa: BLE001 - a bug must not silently end the I/O (the watchdog ramp lives here)
                self.io_errors += 1
                if self.io_errors == 1 or self.io_errors % 1000 == 0:
                    self.get_logger().error(f"I/O loop error #{self.io_errors}: {type(err).__name__}: {err}")
                if not rclpy.ok(context=self.context):
                    return
                self._stop.wait(0.01)

    def _publish_states(self, readings, clock) -> None:
        # sample times are on the link's monotonic clock; shift them onto the node clock
        shift = clock.now().nanoseconds - round(self.link.clock() * 1e9)
        for t, r in readings:
            msg = JointState()
            msg.header.stamp = Time(nanoseconds=round(t * 1e9) + shift).to_msg()
            msg.header.frame_id = self.cfg.frame_id
            msg.name = ["stage"]
            msg.position = [r.position_m]
            msg.effort = [r.applied_v]
            self.pub_state.publish(msg)

    def stop_io(self) -> None:
        """Stop the I/O thread (before the shutdown ramp, which runs in the caller's thread)."""
        self._stop.set()
        self.link.wake()
        self._io.join(2.0)

    # ------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self) -> None:
        h = self.link.snapshot()
        self._log_link(h)
        self.pub_diag.publish(self.diagnostics(h))

    def _log_link(self, h: LinkHealth) -> None:
        """A lost and a regained link in the log too (only /diagnostics showed them)."""
        seen = getattr(self, "_seen_link", (0, 0))
        if h.disconnects > seen[0]:
            self.get_logger().warning(f"link to the device lost ({h.last_link_error or 'no reason given'}); "
                                      "reconnecting, the output held at the device")
        if h.connects > seen[1] and seen[1] > 0:
            self.get_logger().info(f"link to the device regained ({h.identity or 'device'})")
        if h.connects == 0 and h.state != "running" and h.last_link_error:  # never connected: say why, not only
            self.get_logger().warning(f"no link to the device yet on {self.cfg.port}: {h.last_link_error}; "
                                      "retrying", throttle_duration_sec=5.0)  # on /diagnostics
        self._seen_link = (h.disconnects, h.connects)

    def diagnostics(self, h: LinkHealth) -> DiagnosticArray:
        """One DiagnosticStatus: ERROR when the link is down or the device reports a severe fault, WARN on
        bad frames, device errors, timeouts or an active watchdog, else OK."""
        prev = getattr(self, "_prev_health", None)
        self._prev_health = h

        def grew(name: str) -> bool:
            return prev is not None and getattr(h, name) != getattr(prev, name)

        bad = sum(h.bad_frames.values())
        bad_prev = sum(prev.bad_frames.values()) if prev is not None else 0
        if h.state != "running":
            level, message = DiagnosticStatus.ERROR, f"link {h.state}: {h.last_link_error or 'connecting'}"
        elif self.io_errors != getattr(self, "_prev_io_errors", 0):
            level, message = DiagnosticStatus.ERROR, f"{self.io_errors} I/O loop errors (see log)"
        elif grew("severe_faults"):
            level, message = DiagnosticStatus.ERROR, f"device fault {h.last_device_error}"
        elif bad != bad_prev or grew("device_errors") or grew("timeouts") or grew("disconnects"):
            level, message = DiagnosticStatus.WARN, "link degraded (bad frames, device errors or timeouts)"
        elif grew("rejected") or self.bad_commands != getattr(self, "_prev_bad_commands", 0):
            level, message = DiagnosticStatus.WARN, ("commands refused (non-finite, far outside the range or "
                                                     "without a voltage): the output holds the last good one")
        elif h.watchdog_active:
            level, message = DiagnosticStatus.WARN, "no commands: holding/ramping to v_safe"
        else:
            level, message = DiagnosticStatus.OK, "running"
        self._prev_io_errors = self.io_errors
        self._prev_bad_commands = self.bad_commands
        kv = {"state": h.state, "port": self.cfg.port, "protocol": self.cfg.protocol, "identity": h.identity,
              "connects": h.connects, "disconnects": h.disconnects, "handshake_failures": h.handshake_failures,
              "samples": h.samples, "lost_samples": h.lost_samples, "timeouts": h.timeouts,
              "bad_frames": bad, **{f"bad_frames.{k}": v for k, v in sorted(h.bad_frames.items())},
              "device_errors": h.device_errors, "severe_faults": h.severe_faults,
              "last_device_error": h.last_device_error, "last_link_error": h.last_link_error,
              "writes": h.writes, "commanded_v": h.commanded_v, "applied_v": h.applied_v,
              "clipped": h.clipped, "rejected": h.rejected, "slew_limited": h.slew_limited,
              "held": h.held, "expired": h.expired, "unexplained": h.unexplained,
              "watchdog_active": h.watchdog_active, "bad_commands": self.bad_commands, "io_errors": self.io_errors,
              "v_min": self.cfg.v_min, "v_max": self.cfg.v_max, "v_safe": self.cfg.v_safe,
              "scheduling": str(self.scheduling)}
        lat = sorted(self._latency)
        if lat:
            kv.update({"latency_ms.p50": lat[len(lat) // 2] * 1e-6,
                       "latency_ms.p99": lat[int(0.99 * (len(lat) - 1))] * 1e-6, "latency_ms.max": lat[-1] * 1e-6})
        app = sorted(self.link.limiter.apply_delays)  # write -> applied, by the device's read-back (s)
        if app:
            kv.update({"apply_ms.p50": app[len(app) // 2] * 1e3, "apply_ms.p95": app[int(0.95 * (len(app) - 1))] * 1e3,
                       "apply_ms.max": app[-1] * 1e3})
        st = diagnostic_status("hyst_driver: stage link", h.identity or self.cfg.port, level, message, kv)
        return diagnostic_array(self, [st])


#: Exit code when the output could not be confirmed at ``v_safe`` on the way out (the device may hold a voltage).
EXIT_UNSAFE = 3


def _shutdown(node: "DriverNode", stopped_by_signal: bool) -> int:
    """On every way out: stop the I/O, ramp the output to ``v_safe`` (confirmed by the read-back), close; exit
    code :data:`EXIT_UNSAFE` when the read-back never confirmed it (exit 0 hid a device left at 100 V)."""
    node.stop_io()
    ok = node.link.ramp_to_safe(max_seconds=_ramp_seconds(node.cfg))
    print(f"hyst_driver_node: {'ramped to' if ok else 'could not confirm'} v_safe = {node.cfg.v_safe} V "
          f"(link {node.link.health.state})" + ("" if ok else "; check the amplifier's output"), file=sys.stderr)
    node.link.close()
    return 0 if ok else EXIT_UNSAFE


def main(args=None) -> int:
    """Console script ``hyst_driver_node``: :func:`hyst_common.node.run_node` with the EventsExecutor (the lowest
    command latency, which the 1 kHz loop needs); on any way out (signal, error in a callback) the output ramps
    to ``v_safe`` before the port closes."""
    return run_node(DriverNode, args, prog="hyst_driver_node", usage=usage(), executor="events",
                    errors=(DriverError, ConfigError), on_exit=_shutdown)


def _ramp_seconds(cfg: DriverConfig) -> float:
    """Time to ramp across the whole window at the safe ramp rate, with margin for a busy host and a reconnect,
    at most 10 s."""
    return min(10.0, 1.5 * (cfg.v_max - cfg.v_min) / min(cfg.slew_max, cfg.safe_ramp_rate) + 1.0)


if __name__ == "__main__":
    sys.exit(main())
