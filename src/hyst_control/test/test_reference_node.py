"""Reference node in an isolated context: publishes the documented trajectory with its rate; bad shapes refused."""
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_control.reference import Reference
from hyst_control.reference_node import ReferenceNode

pytestmark = pytest.mark.ros


def test_publishes_sine_with_rate_and_validates_parameters():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = ReferenceNode(context=ctx, cli_args=["--ros-args", "-p", "shape:=sine", "-p", "frequency:=2.0",
                                                "-p", "rate:=200.0"])
    peer = rclpy.create_node("peer", context=ctx)
    got = []
    peer.create_subscription(JointState, "/stage/reference", got.append, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(peer)
    try:
        end = time.monotonic() + 10
        while len(got) < 40 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        assert len(got) >= 40
        ref = Reference("sine", 10e-6, 2.0, 15e-6)
        t0 = node._t_start  # ns of the trajectory's t = 0
        for m in got:
            r, v = ref.sample((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec - t0) * 1e-9)
            assert m.position[0] == pytest.approx(r, abs=1e-12)
            assert m.velocity[0] == pytest.approx(v, abs=1e-9)
        for m in got:  # what the in-process loop samples is what was published at that time
            t_ns = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            assert node.sample_at(t_ns) == (m.position[0], m.velocity[0])
        res = node.set_parameters([Parameter("shape", value="square")])[0]
        assert not res.successful and "unknown reference shape" in res.reason
        assert node.set_parameters([Parameter("shape", value="c1")])[0].successful
    finally:
        node.destroy_node()
        peer.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_a_sine_keeps_its_phase_when_its_frequency_changes():
    """Toggling 1 ↔ 2 Hz stepped the reference by up to 17 µm (time kept, phase not); now the sine continues from
    the phase it reached, a shape change still restarts the trajectory at its own t = 0."""
    import math

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = ReferenceNode(context=ctx, cli_args=["--ros-args", "-p", "frequency:=1.0"])
    try:
        dt_ns = 1_000_000  # 1 kHz, as the loop node samples it
        r = [node.sample_at(k * dt_ns)[0] for k in range(1, 321)]
        k0 = 321
        for f, n in ((2.0, 330), (1.0, 337), (3.7, 413), (1.0, 300)):
            assert node.set_parameters([Parameter("frequency", value=f)])[0].successful
            r += [node.sample_at(k * dt_ns)[0] for k in range(k0, k0 + n)]
            k0 += n
        steps = [abs(b - a) for a, b in zip(r, r[1:])]
        bound = 10e-6 * 2 * math.pi * 3.7 * 1e-3 * 1.05  # the fastest sine's largest step per sample
        assert max(steps) <= bound, max(steps)
        assert max(r) > 24e-6 and min(r) < 6e-6  # it still runs its full 5–25 µm
        assert node.set_parameters([Parameter("shape", value="step")])[0].successful
        node.sample_at(k0 * dt_ns)
        assert node._t_start == k0 * dt_ns and node._shift == 0.0
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
