"""hyst_driver_node: the real stage behind the same topics and parameters as the sim.

Publishes ``/stage/state`` (JointState: ``position[0]`` m, ``effort[0]`` applied V, ``header.stamp`` = time the
sample arrived) and ``/diagnostics``; subscribes ``/stage/command`` (``effort[0]`` V). All serial work happens
in one I/O thread (:class:`hyst_driver.transport.DeviceLink`): commands wake it at once, samples are published
from it as they arrive, a lost port is reopened with backoff. Voltages leave only through the limiter
(:mod:`hyst_driver.safety`); when commands stop for ``command_timeout`` and on shutdown the output ramps to
``v_safe`` at ``slew_max``.
"""
from __future__ import annotations

import math
import sys
import threading
from dataclasses import dataclass, replace

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_sim.profiles import get_profile

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

    def validate(self) -> "DriverConfig":
        """Cross-parameter checks; raises :class:`ConfigError` with a reason."""
        prof = get_profile(self.profile)
        if not self.port:
            raise ConfigError("parameter 'port' is empty: give the device path, e.g. -p port:=/dev/ttyACM0 "
                              "(without hardware: run hyst_emulator and use the path it prints)")
        if self.protocol not in PROTOCOLS:
            raise ConfigError(f"protocol {self.protocol!r} unknown; choose one of {', '.join(PROTOCOLS)}")
        if not prof.v_min <= self.v_min < self.v_max <= prof.v_max:
            raise ConfigError(f"need {prof.v_min} <= v_min < v_max <= {prof.v_max} V for profile {prof.name}, "
                              f"got v_min={self.v_min}, v_max={self.v_max}")
        lim = self.limits()
        if lim.slew_max * lim.dt_max < 1e-6:
            raise ConfigError(f"slew_max {self.slew_max} V/s moves less than 1 uV per sample at {self.rate} Hz")
        if self.link_timeout <= 5.0 / self.rate:
            raise ConfigError(f"link_timeout {self.link_timeout} s must exceed 5 samples ({5.0 / self.rate} s)")
        return self

    def limits(self) -> Limits:
        return Limits(self.v_min, self.v_max, self.slew_max, self.v_safe, dt_max=1.0 / self.rate,
                      safe_ramp_rate=self.safe_ramp_rate)


def _fp(lo: float, hi: float) -> list[FloatingPointRange]:
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


class DriverNode(Node):
    """Serial driver for the PEA/GMA amplifier and displacement sensor (see module docstring)."""

    #: Parameters that need a new connection; changing them at run time is refused with a reason.
    RESTART = ("port", "baud", "protocol", "rate", "profile", "counts_to_m", "link_timeout")

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_driver", **kwargs)
        d = ParameterDescriptor
        self.declare_parameter("profile", "pea", d(description="actuator profile: pea (0..150 V) | gma (+-5 V); "
                                                               "sets the defaults and ranges of the limits",
                                                   read_only=True))
        prof = get_profile(self.get_parameter("profile").value)  # ConfigError for a bad name → main()
        lo, hi = prof.v_min, prof.v_max
        self.declare_parameter("port", "", d(description="serial device or pty path (stable /dev/serial/by-id/... "
                                                         "link recommended)"))
        self.declare_parameter("baud", 921600, d(description="UART baud rate (ignored by USB-CDC and ptys)",
                                                 integer_range=[IntegerRange(from_value=1200, to_value=4000000,
                                                                             step=1)]))
        self.declare_parameter("protocol", "ascii", d(description="device protocol: ascii (HDB/1, streamed, "
                                                                  "CRC-8) | gcs (GCS-like, polled)"))
        self.declare_parameter("rate", 1000.0, d(description="sample rate, Hz", floating_point_range=_fp(1, 2000)))
        self.declare_parameter("counts_to_m", prof.sensor_resolution,
                               d(description="metres per sensor count (ascii protocol; gcs reports um)",
                                 floating_point_range=_fp(1e-12, 1e-3)))
        self.declare_parameter("v_min", lo, d(description="lowest voltage ever sent, V", floating_point_range=_fp(lo, hi)))
        self.declare_parameter("v_max", hi, d(description="highest voltage ever sent, V", floating_point_range=_fp(lo, hi)))
        self.declare_parameter("slew_max", prof.slew_max, d(description="largest voltage rate, V/s",
                                                            floating_point_range=_fp(1e-3, 1e9)))
        self.declare_parameter("command_timeout", 0.2, d(description="no command for this long (s): ramp to v_safe",
                                                         floating_point_range=_fp(1e-3, 3600)))
        self.declare_parameter("v_safe", prof.v_safe, d(description="voltage ramped to when commands stop and on "
                                                                    "shutdown, V", floating_point_range=_fp(lo, hi)))
        self.declare_parameter("safe_ramp_rate", 100.0, d(description="rate of the ramp to v_safe (watchdog, "
                                                                       "shutdown), V/s; capped at slew_max",
                                                          floating_point_range=_fp(1e-3, 1e9)))
        self.declare_parameter("link_timeout", 0.5, d(description="no sample for this long (s): reconnect",
                                                      floating_point_range=_fp(0.005, 60)))
        self.declare_parameter("frame_id", "stage", d(description="header.frame_id of /stage/state"))
        self.cfg = self._read_config({}).validate()
        self.add_on_set_parameters_callback(self._on_set)

        c = self.cfg
        adapter = make_adapter(c.protocol, c.counts_to_m, (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)))
        self.link = DeviceLink(SerialTransport(c.port, c.baud), adapter, c.limits(), round(c.rate),
                               command_timeout=c.command_timeout, link_timeout=c.link_timeout)
        self.pub_state = self.create_publisher(JointState, "/stage/state", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "/stage/command", self._on_command, 10)
        self.create_timer(1.0, self._publish_diagnostics)
        self.bad_commands = 0
        self._stop = threading.Event()
        self._io = threading.Thread(target=self._io_loop, name="hyst_driver_io", daemon=True)
        self._io.start()
        self.get_logger().info(f"{c.protocol} device on {c.port}, profile {c.profile}, {c.rate:g} Hz, "
                               f"limits [{c.v_min}, {c.v_max}] V, {c.slew_max:g} V/s, safe {c.v_safe} V")

    # ------------------------------------------------------------ parameters
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
            return
        self.link.command(float(msg.effort[0]))

    def _io_loop(self) -> None:
        link, clock = self.link, self.get_clock()
        while not self._stop.is_set():
            link.wait(link.next_deadline() - link.clock())
            for _t, r in link.service():
                msg = JointState()
                msg.header.stamp = clock.now().to_msg()
                msg.header.frame_id = self.cfg.frame_id
                msg.name = ["stage"]
                msg.position = [r.position_m]
                msg.effort = [r.applied_v]
                try:
                    self.pub_state.publish(msg)
                except Exception:  # context shutting down under us: the main thread ends the loop
                    return

    def stop_io(self) -> None:
        """Stop the I/O thread (before the shutdown ramp, which runs in the caller's thread)."""
        self._stop.set()
        self.link.wake()
        self._io.join(2.0)

    # ------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self) -> None:
        self.pub_diag.publish(self.diagnostics(self.link.snapshot()))

    def diagnostics(self, h: LinkHealth) -> DiagnosticArray:
        """One DiagnosticStatus: ERROR when the link is down or the device reports a severe fault, WARN on
        bad frames, device errors, timeouts or an active watchdog, else OK."""
        prev = getattr(self, "_prev_health", None)
        self._prev_health = h

        def grew(name: str) -> bool:
            return prev is not None and getattr(h, name) != getattr(prev, name)

        bad = sum(h.bad_frames.values())
        bad_prev = sum(prev.bad_frames.values()) if prev is not None else 0
        st = DiagnosticStatus(name="hyst_driver: stage link", hardware_id=h.identity or self.cfg.port)
        if h.state != "running":
            st.level, st.message = DiagnosticStatus.ERROR, f"link {h.state}: {h.last_link_error or 'connecting'}"
        elif grew("severe_faults"):
            st.level, st.message = DiagnosticStatus.ERROR, f"device fault {h.last_device_error}"
        elif bad != bad_prev or grew("device_errors") or grew("timeouts") or grew("disconnects"):
            st.level, st.message = DiagnosticStatus.WARN, "link degraded (bad frames, device errors or timeouts)"
        elif h.watchdog_active:
            st.level, st.message = DiagnosticStatus.WARN, "no commands: holding/ramping to v_safe"
        else:
            st.level, st.message = DiagnosticStatus.OK, "running"
        kv = {"state": h.state, "port": self.cfg.port, "protocol": self.cfg.protocol, "identity": h.identity,
              "connects": h.connects, "disconnects": h.disconnects, "handshake_failures": h.handshake_failures,
              "samples": h.samples, "lost_samples": h.lost_samples, "timeouts": h.timeouts,
              "bad_frames": bad, **{f"bad_frames.{k}": v for k, v in sorted(h.bad_frames.items())},
              "device_errors": h.device_errors, "severe_faults": h.severe_faults,
              "last_device_error": h.last_device_error, "last_link_error": h.last_link_error,
              "writes": h.writes, "commanded_v": h.commanded_v, "applied_v": h.applied_v,
              "clipped": h.clipped, "rejected": h.rejected, "slew_limited": h.slew_limited,
              "watchdog_active": h.watchdog_active, "bad_commands": self.bad_commands,
              "v_min": self.cfg.v_min, "v_max": self.cfg.v_max, "v_safe": self.cfg.v_safe}
        st.values = [KeyValue(key=k, value=f"{v:.6g}" if isinstance(v, float) else str(v)) for k, v in kv.items()]
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.get_clock().now().to_msg()
        return arr


def main(args=None) -> int:
    """Console script ``hyst_driver_node``."""
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = DriverNode()
        try:
            from rclpy.experimental import EventsExecutor  # lowest command latency (commands wake the I/O thread)
            executor = EventsExecutor()
        except ImportError:  # pragma: no cover - older rclpy
            executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (DriverError, ConfigError, ValueError) as err:  # bad user input: one line, non-zero exit
        print(f"hyst_driver_node: {err}", file=sys.stderr)
        code = 2
    except Exception as err:
        if node is not None and not rclpy.ok():
            pass  # a callback tripped over the context going down under a signal: that is the shutdown
        elif type(err).__module__.startswith(("hyst_", "rclpy")):
            print(f"hyst_driver_node: {err}", file=sys.stderr)
            code = 2
        else:
            raise
    finally:
        if node is not None:
            node.stop_io()
            ok = node.link.ramp_to_safe(max_seconds=_ramp_seconds(node.cfg))
            print(f"hyst_driver_node: {'ramped to' if ok else 'could not confirm'} v_safe = {node.cfg.v_safe} V "
                  f"(link {node.link.health.state})", file=sys.stderr)
            node.link.close()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def _ramp_seconds(cfg: DriverConfig) -> float:
    """Time to ramp across the whole window at the safe ramp rate, plus margin for a reconnect, at most 10 s."""
    return min(10.0, (cfg.v_max - cfg.v_min) / min(cfg.slew_max, cfg.safe_ramp_rate) + 1.0)


if __name__ == "__main__":
    sys.exit(main())
