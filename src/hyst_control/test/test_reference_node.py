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
