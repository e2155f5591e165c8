"""``profile custom`` through the real driver: hyst_driver_node on a ±10 V amplifier, the emulator on that stage's
model (its params file), over a pty — as the sim node's ``profile custom`` stands in for it."""
from __future__ import annotations

import time

import pytest

from hyst_bringup.emulator import build_device
from hyst_common.errors import ConfigError



def test_build_device_runs_a_custom_stage_on_its_own_range(ten_volt_stage):
    dev = build_device("custom", 1000.0, params_file=ten_volt_stage, v_range=(-10.0, 10.0))
    assert dev.v_range == (-10.0, 10.0)
    with pytest.raises(ConfigError, match="needs --params-file"):
        build_device("custom", 1000.0, v_range=(-10.0, 10.0))
    with pytest.raises(ConfigError, match="needs --v-min and --v-max"):
        build_device("custom", 1000.0, params_file=ten_volt_stage, v_range=(None, 10.0))
    with pytest.raises(ConfigError, match="has its own"):
        build_device("pea", 1000.0, v_range=(0.0, 100.0))


@pytest.mark.ros
def test_the_driver_sends_a_custom_amplifiers_range_and_clips_beyond_it(ten_volt_stage):
    """9 V is applied as sent (beyond the GMA's ±5 V: the pea/gma profiles' ranges no longer bound the rig), 20 V
    is clipped to the amplifier's 10 V; a range beyond ±1 kV or without its ends is refused at start."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from hyst_driver.driver_node import DriverNode
    from hyst_driver.emulator import PtyEmulator

    emu = PtyEmulator(build_device("custom", 1000.0, params_file=ten_volt_stage,
                                   v_range=(-10.0, 10.0))).start()
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = peer = None
    try:
        over = [Parameter("profile", value="custom"), Parameter("v_min", value=-10.0),
                Parameter("v_max", value=10.0), Parameter("port", value=emu.link)]
        node = DriverNode(context=ctx, parameter_overrides=over)
        c = node.cfg
        assert (c.v_min, c.v_max, c.v_safe, c.slew_max) == (-10.0, 10.0, 0.0, 2e4)
        assert node.describe_parameter("v_max").floating_point_range[0].to_value == 1000.0
        assert not node.set_parameters([Parameter("v_max", value=1001.0)])[0].successful
        peer = rclpy.create_node("peer", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(peer)
        applied: list[float] = []
        want = {"v": 9.0}
        pub = peer.create_publisher(JointState, "/stage/command", 10)

        def answer(msg: JointState) -> None:  # every sample answered, as a controller does
            applied.append(float(msg.effort[0]))
            cmd = JointState()
            cmd.header.stamp = msg.header.stamp
            cmd.effort = [want["v"]]
            pub.publish(cmd)

        peer.create_subscription(JointState, "/stage/state", answer, 100)

        def spin_until(cond, timeout=30.0) -> bool:
            end = time.monotonic() + timeout
            while time.monotonic() < end and not cond():
                ex.spin_once(timeout_sec=0.01)
            return cond()

        assert spin_until(lambda: any(abs(v - 9.0) < 1e-6 for v in applied)), applied[-5:]
        want["v"] = 20.0
        assert spin_until(lambda: bool(applied) and abs(applied[-1] - 10.0) < 1e-6), applied[-5:]
        assert max(applied) <= 10.0 + 1e-9
    finally:
        if node is not None:
            node.stop_io()
            node.link.close()
            node.destroy_node()
        if peer is not None:
            peer.destroy_node()
        rclpy.try_shutdown(context=ctx)
        emu.stop()


@pytest.mark.ros
@pytest.mark.parametrize(("args", "why"), [
    (("-p", "profile:=custom", "-p", "port:=/dev/null"), "profile custom needs v_min and v_max"),
    (("-p", "profile:=custom", "-p", "port:=/dev/null", "-p", "v_min:=-10.0", "-p", "v_max:=2000.0"), "v_max"),
])
def test_a_custom_driver_without_a_range_exits_2_with_one_line(args, why):
    import subprocess
    import sys

    cmd = [sys.executable, "-c", "import sys; from hyst_driver.driver_node import main; sys.exit(main())",
           "--ros-args", *args]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and why in r.stderr and "Traceback" not in r.stderr, r.stderr
