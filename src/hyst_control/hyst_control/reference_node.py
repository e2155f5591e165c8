"""hyst_reference_node: publishes ``/stage/reference`` (``position[0]`` r in m, ``velocity[0]`` ṙ in m/s).

Parameters: ``shape`` (step, ramp, step+ramp, sine, c1, c2, c3, case3, constant), ``amplitude`` (m),
``frequency`` (Hz), ``offset`` (m), ``t0`` (s), ``rate`` (Hz), ``duration`` (s, 0 = forever; afterwards the last
value is held). Time starts at the first publication and restarts when the shape changes; a sine whose frequency
changes keeps its phase (no step, as a function generator sweeps). Every value is
validated in the on-set callback (:class:`hyst_control.reference.Reference` checks it) and applied by swapping
the frozen reference object.
"""
from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.timer import Timer
from sensor_msgs.msg import JointState

from hyst_common.node import AtomicParametersNode, fp_range, run_node

from .errors import ControlError
from .reference import SHAPES, Reference

__all__ = ["ReferenceNode", "main"]


class ReferenceNode(AtomicParametersNode):
    """Publishes a :class:`Reference` at ``rate``; see the module docstring."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_reference", **kwargs)
        d = self.declare_parameter
        d("shape", "sine", ParameterDescriptor(description=" | ".join(SHAPES)))
        d("amplitude", 10e-6, ParameterDescriptor(description="amplitude (m)", floating_point_range=fp_range(0, 1e-3)))
        d("frequency", 1.0, ParameterDescriptor(description="frequency (Hz)", floating_point_range=fp_range(0, 500)))
        d("offset", 15e-6, ParameterDescriptor(description="offset / start level (m)",
                                               floating_point_range=fp_range(-1e-3, 1e-3)))
        d("t0", 0.1, ParameterDescriptor(description="start of steps and ramps (s)",
                                         floating_point_range=fp_range(0, 1e4)))
        d("rate", 1000.0, ParameterDescriptor(description="publication rate (Hz)",
                                              floating_point_range=fp_range(1, 5000)))
        d("duration", 0.0, ParameterDescriptor(description="seconds to run, then hold (0 = forever)",
                                               floating_point_range=fp_range(0, 1e6)))
        self._ref = self._build()
        self._rate = float(self.get_parameter("rate").value)
        self._duration = float(self.get_parameter("duration").value)
        self._t_start: int | None = None  # clock time (ns) of the first sample of this trajectory
        self._t_last: int | None = None   # clock time (ns) of the newest sample
        self._shift = 0.0  # s added to the trajectory's time: a sine's phase kept across frequency changes
        self._pub = self.create_publisher(JointState, "/stage/reference", 10)
        self._timer: Timer | None = self.create_timer(1.0 / self._rate, self._tick)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._after_set)

    def _build(self, changes: dict | None = None) -> Reference:
        def get(n):
            return changes[n] if changes and n in changes else self.get_parameter(n).value

        return Reference(shape=str(get("shape")), amplitude=float(get("amplitude")),
                         frequency=float(get("frequency")), offset=float(get("offset")), t0=float(get("t0")))

    def _on_set(self, params) -> SetParametersResult:
        try:
            self._build({p.name: p.value for p in params})
        except (ControlError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _after_set(self, params) -> None:
        old = self._ref
        self._ref = new = self._build()
        self._duration = float(self.get_parameter("duration").value)
        if new.shape != old.shape:
            self._t_start = None  # a new trajectory starts at its own t = 0
            self._shift = 0.0
        elif new.shape == "sine" and new.frequency != old.frequency and new.frequency > 0 \
                and self._t_start is not None and self._t_last is not None:
            # the phase reached so far, at the new frequency: f_new (t + shift') = f_old (t + shift), one period
            t = (self._t_last - self._t_start) * 1e-9
            cycles = old.frequency * (t + self._shift)
            self._shift = (cycles % 1.0) / new.frequency - t
        rate = float(self.get_parameter("rate").value)
        if rate != self._rate:
            self._rate = rate
            if self._timer is not None:  # driven by another clock (follow_clock): no timer to re-make
                self.destroy_timer(self._timer)
                self._timer = self.create_timer(1.0 / rate, self._tick)

    def sample_at(self, t_ns: int) -> tuple[float, float]:
        """(r in m, ṙ in m/s) of the trajectory at clock time ``t_ns`` (ns), as a publication stamped then carries.

        The trajectory starts at the first time asked for (published or sampled). ``hyst_loop_node`` samples it
        in process at each state's time, exactly, instead of a topic hop per sample.
        """
        if self._t_start is None:
            self._t_start = t_ns
        self._t_last = t_ns
        t = max(t_ns - self._t_start, 0) * 1e-9
        hold = self._duration > 0 and t > self._duration
        r, v = self._ref.sample((min(t, self._duration) if hold else t) + self._shift)
        return float(r), 0.0 if hold or not math.isfinite(v) else float(v)

    def follow_clock(self) -> None:
        """Stop publishing on this node's own timer: another clock drives the trajectory (the lockstep stage's,
        through :meth:`publish_at`). On the wall clock a lockstep run followed a 4.7 Hz sine for a 10 Hz one and
        differed run to run."""
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def publish_at(self, t_ns: int) -> None:
        """Publish the trajectory's sample at clock time ``t_ns`` (ns), stamped so."""
        r, v = self.sample_at(t_ns)
        msg = JointState()
        msg.header.stamp = Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
        msg.name = ["stage"]
        msg.position = [r]
        msg.velocity = [v]
        self._pub.publish(msg)

    @property
    def rate(self) -> float:
        """Publication rate (Hz)."""
        return self._rate

    def _tick(self) -> None:
        self.publish_at(self.get_clock().now().nanoseconds)


def main(args=None) -> int:
    """Console script ``hyst_reference_node`` (``--ros-args -p shape:=sine -p frequency:=5.0``)."""
    return run_node(ReferenceNode, args, prog="hyst_reference_node", errors=(ControlError,),
                    usage="usage: hyst_reference_node [--ros-args -p NAME:=VALUE ...]\n\n" + __doc__)


if __name__ == "__main__":
    raise SystemExit(main())
