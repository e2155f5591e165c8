"""The driver node: parameters (declared ranges, on-set validation), and a node process under injected faults."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_driver.emulator import FAULTS, PtyEmulator
from hyst_driver.linear_stage import linear_device

pytestmark = pytest.mark.ros


@pytest.fixture
def emu():
    e = PtyEmulator(linear_device("pea", 1000.0)).start()
    yield e
    e.stop()


#: Deadline (s) of every wait: generous; tests wait for conditions, never a fixed time before asserting.
DEADLINE = 20.0


def _spin_until(ex, pred, timeout: float = DEADLINE) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if pred():
            return True
        ex.spin_once(timeout_sec=0.01)
    return pred()


def _wait(pred, timeout: float = DEADLINE) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


def test_parameters_declared_with_ranges_and_validated_on_set(ctx, emu):
    from rclpy.executors import SingleThreadedExecutor

    from hyst_driver.driver_node import DriverNode

    node = DriverNode(context=ctx, parameter_overrides=[Parameter("port", value=emu.link)])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        d = node.describe_parameter("v_max")
        assert d.floating_point_range[0].from_value == 0.0 and d.floating_point_range[0].to_value == 150.0
        assert node.describe_parameter("profile").read_only
        bad = {
            "v_max": 200.0,             # outside the declared range
            "v_safe": 151.0,
            "rate": 5000.0,
            "port": "/dev/other",       # needs a restart
            "protocol": "gcs",
        }
        for name, value in bad.items():
            r = node.set_parameters([Parameter(name, value=value)])[0]
            assert not r.successful and r.reason, name
        r = node.set_parameters_atomically([Parameter("v_min", value=100.0), Parameter("v_max", value=50.0)])
        assert not r.successful and "v_min" in r.reason and node.cfg.v_min == 0.0
        r = node.set_parameters_atomically([Parameter("v_max", value=100.0), Parameter("slew_max", value=5e4)])
        assert r.successful and node.cfg.v_max == 100.0 and node.cfg.slew_max == 5e4
        r = node.set_parameters([Parameter("v_safe", value=140.0)])[0]  # now outside [v_min, v_max]
        assert not r.successful and "v_safe" in r.reason and node.cfg.v_safe == 0.0
        # swapped into the running link (by its I/O thread), which is running
        assert _spin_until(ex, lambda: node.link.limiter.limits.v_max == 100.0 and node.link.health.state == "running")
    finally:
        node.stop_io()
        node.link.close()
        node.destroy_node()


def test_a_custom_window_widened_at_run_time_keeps_the_link(ctx, emu):
    """With profile custom the read-backs were believed only within the start-up window (0-10 V here): after
    v_max 50 V every read-back above 11 V was 'implausible', the link dropped and never came back, and the
    device stayed at 15 V after SIGINT."""
    from rclpy.executors import SingleThreadedExecutor

    from hyst_driver.driver_node import DriverNode

    node = DriverNode(context=ctx, parameter_overrides=[
        Parameter("port", value=emu.link), Parameter("profile", value="custom"), Parameter("v_min", value=0.0),
        Parameter("v_max", value=10.0)])
    peer = rclpy.create_node("peer", context=ctx)
    pub = peer.create_publisher(JointState, "/stage/command", 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(peer)
    try:
        assert _spin_until(ex, lambda: node.link.health.state == "running")
        assert node.set_parameters([Parameter("v_max", value=50.0)])[0].successful

        def at_40() -> bool:
            pub.publish(JointState(effort=[40.0]))
            return abs(node.link.health.applied_v - 40.0) < 1e-3
        assert _spin_until(ex, at_40)
        assert node.link.health.state == "running" and node.link.health.bad_frames.get("implausible", 0) == 0
        node.stop_io()
        assert node.link.ramp_to_safe(5.0)
    finally:
        node.stop_io()
        node.link.close()
        peer.destroy_node()
        node.destroy_node()


def test_gma_profile_sets_limit_defaults_and_ranges(ctx, tmp_path):
    from hyst_driver.driver_node import DriverNode

    node = DriverNode(context=ctx, parameter_overrides=[Parameter("profile", value="gma"),
                                                        Parameter("port", value=str(tmp_path / "no_such_port"))])
    try:
        c = node.cfg
        assert (c.v_min, c.v_max, c.v_safe, c.slew_max) == (-5.0, 5.0, 0.0, 1.0e4)
        assert node.describe_parameter("v_min").floating_point_range[0].from_value == -5.0
        assert not node.set_parameters([Parameter("v_max", value=10.0)])[0].successful
        # no port: the node is up, reports the link down and keeps retrying
        assert _wait(lambda: "no_such_port" in node.link.snapshot().last_link_error)
        h = node.link.snapshot()
        assert h.state == "disconnected" and "no_such_port" in h.last_link_error
        d = node.diagnostics(h).status[0]
        assert d.level == d.ERROR and "disconnected" in d.message
    finally:
        node.stop_io()
        node.link.close()
        node.destroy_node()


def _node_cmd(*ros_args: str) -> list[str]:
    return [sys.executable, "-c", "import sys; from hyst_driver.driver_node import main; sys.exit(main())",
            "--ros-args", *ros_args]


def test_bad_startup_parameters_give_one_line_and_exit_2():
    r = subprocess.run(_node_cmd("-p", "port:=''"), capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "port" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run(_node_cmd("-p", "port:=/dev/null", "-p", "v_min:=100.0", "-p", "v_max:=50.0"),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "v_min" in r.stderr and "Traceback" not in r.stderr


class _Probe:
    """Test-side ROS endpoints: hostile command publisher, state and diagnostics listeners."""

    def __init__(self, ctx) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.node = rclpy.create_node("probe", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.states: list[JointState] = []
        self.diag: list[dict] = []
        self.node.create_subscription(JointState, "/stage/state", self._state, 100)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._diag, 10)
        self.pub = self.node.create_publisher(JointState, "/stage/command", 100)
        self.k = 0

    def _state(self, msg: JointState) -> None:
        self.states.append(msg)
        self.k += 1
        cmd = JointState()
        cmd.header.stamp = msg.header.stamp
        if self.k % 50 == 0:
            cmd.effort = []                     # malformed: must be counted, never fatal
        else:
            specials = [math.nan, math.inf, -math.inf, 1e300, 500.0, -80.0]
            cmd.effort = [specials[self.k % 6] if self.k % 7 == 0 else 60.0 + 70.0 * math.sin(self.k / 50.0)]
        self.pub.publish(cmd)

    def _diag(self, msg: DiagnosticArray) -> None:
        s = msg.status[0]
        d = {kv.key: kv.value for kv in s.values}
        d["level"], d["message"] = int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else s.level, \
            s.message
        self.diag.append(d)

    def spin(self, seconds: float) -> None:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            self.ex.spin_once(timeout_sec=0.005)

    def wait_diag(self, pred, timeout: float) -> dict | None:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            n = len(self.diag)
            self.spin(0.05)
            if len(self.diag) > n and pred(self.diag[-1]):
                return self.diag[-1]
        return None

    def wait_states(self, n: int, timeout: float) -> bool:
        """Spin until ``n`` more /stage/state samples arrived (the link is delivering again)."""
        goal = len(self.states) + n
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end and len(self.states) < goal:
            self.spin(0.01)
        return len(self.states) >= goal


def max_slew_step(dev) -> float:
    """Largest step (V) between consecutive commands the device received; across a (re)connection handshake
    the step from the voltage it applied then (which the driver read back and re-seeded its limiter from)."""
    rx, applied = dev.received, dev.applied_at_receipt
    marks = set(dev.identified_at)  # index of the first command after each handshake
    worst = 0.0
    for k in range(1, len(rx)):
        worst = max(worst, abs(rx[k] - (applied[k] if k in marks else rx[k - 1])))
    return worst


def max_applied_step(dev) -> float:
    """Largest change (V) of the voltage the amplifier applied between consecutive device samples: the step the
    stage feels, whichever commands produced it (two delivered within one sample count as one step)."""
    a = dev.applied
    return max((abs(a[k] - a[k - 1]) for k in range(1, len(a))), default=0.0)


def test_applied_step_check_sees_two_commands_within_one_sample():
    class Dev:
        applied = [10.0, 10.0, 30.0, 50.0]
    assert max_applied_step(Dev) == pytest.approx(20.0)
    Dev.applied = [10.0, 10.0, 50.0]  # 30 V and 50 V arrived within one sample: received steps 20 + 20 V
    assert max_applied_step(Dev) == pytest.approx(40.0)


def test_slew_check_judges_steps_across_a_reconnect_from_the_applied_voltage():
    class Dev:
        received = [10.0, 30.0, 50.0, 70.5, 90.0]
        applied_at_receipt = [10.0, 10.0, 30.0, 50.5, 70.5]
        identified_at = [3]  # reconnected before the fourth command; the amplifier had applied 50.5 V
    assert max_slew_step(Dev) == pytest.approx(20.0)
    Dev.identified_at = []  # without the handshake the 20.5 V step is a violation
    assert max_slew_step(Dev) == pytest.approx(20.5)


@pytest.mark.slow
def test_node_survives_every_fault_class_and_ramps_to_safe_on_sigint(ctx, emu):
    """Each fault class 100 times into one running node: after every fault samples flow again (the node stays
    up and reconnects after each unplug), the faults are counted on /diagnostics, and no voltage outside the
    limits or faster than the slew limit ever reaches the device, while the command stream is hostile. The
    slew limit is judged against the voltage the amplifier applied at each of its samples.

    Measured with three CPU hogs beside it (load 8.5-13.7 on 2 cores; ``pytest -s`` prints the verdict line):
    before the in-flight envelope, a 100 V applied step (38.3 V between consecutive writes); with it, 14 of 14
    runs (commit 3623da3; 1.24 M device samples, 104-126 reconnects a run) max applied step 20.000000 V, applied
    voltage in [10, 120] V. Three of those runs failed elsewhere: one unplug of 100 not recovered within 20 s,
    the shutdown race fixed after (6bdd3bc), and one shutdown ramp not confirmed within its time.
    """
    runs = 100
    proc = subprocess.Popen(_node_cmd("-p", f"port:={emu.link}", "-p", "v_min:=10.0", "-p", "v_max:=120.0",
                                      "-p", "slew_max:=20000.0", "-p", "v_safe:=20.0", "-p", "link_timeout:=0.2",
                                      "-p", "command_timeout:=0.05"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    probe = _Probe(ctx)
    try:
        assert probe.wait_diag(lambda d: d["state"] == "running", 20.0), proc.poll()
        recovered = dict.fromkeys(FAULTS, 0)
        for fault in FAULTS:
            for _ in range(runs):
                n = emu.injected[fault]
                emu.inject(fault, 0.05 if fault == "timeout" else 0.03)
                assert _wait(lambda: emu.injected[fault] > n), f"emulator never applied {fault}"
                probe.spin(0.06)  # pacing only (the fault plays out); what follows waits for events
                recovered[fault] += probe.wait_states(5, DEADLINE)  # samples again: stayed up / reconnected
            assert proc.poll() is None, f"node died after {fault}"
        assert recovered == dict.fromkeys(FAULTS, runs), recovered
        d = probe.wait_diag(lambda d: d["state"] == "running", DEADLINE)
        assert d is not None
        assert probe.wait_states(100, DEADLINE)  # samples flow again after the faults
        last = probe.wait_diag(lambda d: True, DEADLINE)
        c = {k: int(last[k]) for k in ("bad_frames", "device_errors", "timeouts", "disconnects", "connects",
                                        "rejected", "clipped", "bad_commands")}
        # Each fault shows in the counters; 5 % may hide behind another event on a loaded host (measured at load
        # 10: 29 extra reconnects after stalls longer than link_timeout; a reconnect discards the stale bytes, one
        # device error with them; an unplug while already reconnecting is no new disconnect).
        least = 0.95 * runs
        assert c["bad_frames"] >= least and c["device_errors"] >= least and c["timeouts"] >= least, c
        assert c["disconnects"] >= least and c["connects"] >= least + 1, c  # every unplug: a reconnect
        assert c["rejected"] > 0 and c["clipped"] > 0 and c["bad_commands"] > 0, c
        assert any(d["level"] != 0 for d in probe.diag), "faults never showed as WARN/ERROR"
        assert all(10.0 <= s.effort[0] <= 120.0 for s in probe.states[-100:])
        assert float(last["latency_ms.p50"]) > 0.0  # answers carry the state stamp: loop latency is reported
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        probe.node.destroy_node()
        rx = emu.device.received
        _wait(lambda: rx and rx[-1] == 20.0)  # the emulator reads the last line in its own time
        a = emu.device.applied
        first = next((k for k, v in enumerate(a) if v != a[0]), 0)
        # printed whatever failed above: the safety verdict of every run (pytest -s) is the measurement
        print(f"\nfault test: max applied step {max_applied_step(emu.device):.6f} V over {len(a)} samples, "
              f"applied in [{min(a[first:]):.6f}, {max(a[first:]):.6f}] V, max received step "
              f"{max_slew_step(emu.device):.6f} V, load {os.getloadavg()[0]:.1f}; node: "
              + " ".join(f"{k}={probe.diag[-1].get(k)}" for k in ("connects", "held", "expired", "unexplained")
                         if probe.diag))
    assert proc.returncode == 0, err
    assert "ramped to v_safe = 20.0 V" in err
    assert rx[-1] == 20.0, rx[-3:]
    assert 10.0 <= min(rx) and max(rx) <= 120.0
    assert max_slew_step(emu.device) <= 20.0 + 1e-6
    # judged against the voltage actually applied, sample by sample (the stage starts at 0 V; the driver's
    # first write is v_min = 10 V, a 10 V step)
    assert max_applied_step(emu.device) <= 20.0 + 1e-6, max_applied_step(emu.device)
    assert 10.0 <= min(a[first:]) and max(a[first:]) <= 120.0


def test_help_lists_every_parameter_and_exits_0(capsys):
    from hyst_driver.driver_node import main, param_table
    from hyst_common.profiles import PEA

    assert main(["hyst_driver_node", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"  {name} " in out for name, *_ in param_table(PEA))
    assert main(["hyst_driver_node", "stray"]) == 2 and "unexpected argument" in capsys.readouterr().err
