"""hyst_common.node: all-or-nothing parameter sets (method and remote service) and the one node runner."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from hyst_common.node import AtomicParametersNode, fp_range

pytestmark = pytest.mark.ros


class Window(AtomicParametersNode):
    """A window [v_min, v_max] that must stay ordered: the case rclpy applied half of."""

    def __init__(self, **kwargs) -> None:
        super().__init__("window", **kwargs)
        for n, v in (("v_min", 0.0), ("v_max", 150.0)):
            self.declare_parameter(n, v, ParameterDescriptor(floating_point_range=fp_range(-200, 200)))
        self.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, params) -> SetParametersResult:
        vals = {n: self.get_parameter(n).value for n in ("v_min", "v_max")}
        vals.update({p.name: p.value for p in params})
        if not vals["v_min"] < vals["v_max"]:
            return SetParametersResult(successful=False, reason="v_min must be below v_max")
        return SetParametersResult(successful=True)


@pytest.fixture
def ctx():
    c = rclpy.Context()
    rclpy.init(context=c)
    yield c
    rclpy.try_shutdown(context=c)


def _values(node) -> tuple[float, float]:
    return node.get_parameter("v_min").value, node.get_parameter("v_max").value


def test_a_set_is_validated_as_one_configuration_locally(ctx):
    node = Window(context=ctx)
    res = node.set_parameters([Parameter("v_min", value=100.0), Parameter("v_max", value=50.0)])
    assert [r.successful for r in res] == [False, False] and "below" in res[0].reason
    assert _values(node) == (0.0, 150.0)  # nothing applied (rclpy alone applied v_min=100, then refused v_max)
    res = node.set_parameters([Parameter("v_max", value=50.0), Parameter("v_min", value=10.0)])
    assert all(r.successful for r in res) and _values(node) == (10.0, 50.0)  # fine as a whole, in any order
    node.destroy_node()


def test_the_remote_service_is_all_or_nothing_too(ctx):
    node = Window(context=ctx)
    peer = rclpy.create_node("peer", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(peer)
    client = AsyncParameterClient(peer, "window")
    try:
        deadline = time.monotonic() + 30
        while not client.services_are_ready() and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        fut = client.set_parameters([Parameter("v_min", value=100.0), Parameter("v_max", value=50.0)])
        ex.spin_until_future_complete(fut, timeout_sec=30)
        results = fut.result().results
        assert [r.successful for r in results] == [False, False]
        assert _values(node) == (0.0, 150.0)
        fut = client.set_parameters([Parameter("nope", value=1.0), Parameter("v_max", value=60.0)])
        ex.spin_until_future_complete(fut, timeout_sec=30)
        assert not any(r.successful for r in fut.result().results)
        assert "nope" in fut.result().results[0].reason and _values(node) == (0.0, 150.0)
    finally:
        ex.shutdown()
        peer.destroy_node()
        node.destroy_node()


@pytest.mark.parametrize("service", ["set_parameters", "set_parameters_atomically"])
def test_a_malformed_parameter_request_is_refused_and_the_node_lives_on(ctx, service):
    """A value of an unknown type code raised inside rclpy's service callback and killed the node (exit 1)."""
    from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterValue
    from rcl_interfaces.srv import SetParameters, SetParametersAtomically

    node = Window(context=ctx)
    peer = rclpy.create_node("peer", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(peer)
    srv = SetParameters if service == "set_parameters" else SetParametersAtomically
    client = peer.create_client(srv, f"/window/{service}")
    try:
        deadline = time.monotonic() + 30
        while not client.service_is_ready() and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        bad = ParameterMsg(name="v_max", value=ParameterValue(type=42))
        good = ParameterMsg(name="v_min", value=ParameterValue(type=3, double_value=10.0))  # 3: DOUBLE
        fut = client.call_async(srv.Request(parameters=[good, bad]))
        ex.spin_until_future_complete(fut, timeout_sec=30)
        res = fut.result()
        results = res.results if service == "set_parameters" else [res.result]
        assert results and not any(r.successful for r in results) and "malformed" in results[0].reason
        assert _values(node) == (0.0, 150.0)  # nothing applied, and the node still answers
        fut = client.call_async(srv.Request(parameters=[good]))
        ex.spin_until_future_complete(fut, timeout_sec=30)
        assert _values(node) == (10.0, 150.0)
    finally:
        ex.shutdown()
        peer.destroy_node()
        node.destroy_node()


def test_a_whole_number_for_a_float_parameter_is_that_number(ctx):
    """``-p v_max:=100`` (or ``zeta1: 1`` in a params file) is an INTEGER to ROS: rclpy refused it at start
    ("expecting type 'DOUBLE'") and in every set; it is the float it says, while a string stays refused."""
    node = Window(context=ctx, cli_args=["--ros-args", "-p", "v_max:=100"])
    try:
        v = node.get_parameter("v_max")
        assert v.value == 100.0 and v.type_ == Parameter.Type.DOUBLE
        assert node.set_parameters([Parameter("v_min", value=-5)])[0].successful
        assert node.get_parameter("v_min").value == -5.0 and node.get_parameter("v_min").type_ == Parameter.Type.DOUBLE
        assert node.set_parameters_atomically([Parameter("v_max", value=120)]).successful
        assert node.get_parameter("v_max").value == 120.0
        assert not node.set_parameters([Parameter("v_max", value="120")])[0].successful
        assert not node.set_parameters([Parameter("v_max", value=500)])[0].successful  # the range still holds
    finally:
        node.destroy_node()


RUNNER = r'''
import sys
from rcl_interfaces.msg import ParameterDescriptor
from hyst_common.node import AtomicParametersNode, fp_range, run_node

class Probe(AtomicParametersNode):
    def __init__(self):
        super().__init__("probe")
        self.declare_parameter("gain", 1.0, ParameterDescriptor(floating_point_range=fp_range(0, 10)))
        print("probe up", flush=True)

sys.exit(run_node(Probe, prog="probe_node", usage="usage: probe_node [--ros-args ...]"))
'''


def _run(*argv: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", RUNNER, *argv], capture_output=True, text=True, timeout=120, **kw)


def test_runner_help_and_argument_errors_before_ros():
    r = _run("--help")
    assert r.returncode == 0 and "usage: probe_node" in r.stdout and not r.stderr.strip()
    r = _run("-h", "--ros-args", "-p", "gain:=1.0")  # help is ours only before --ros-args
    assert r.returncode == 0 and "usage: probe_node" in r.stdout
    r = _run("--ros-args", "-h")  # after it, rclpy's: a ROS argument it does not know is one line, exit 2
    assert r.returncode == 2 and "usage" not in r.stdout and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "probe_node: error:" in r.stderr
    r = _run("--bogus")
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "probe_node: error:" in r.stderr


def test_runner_start_up_error_is_one_line_exit_2():
    r = _run("--ros-args", "-p", "gain:=-5.0")
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("probe_node: error:"), r.stderr
    assert "gain" in lines[0] and "Traceback" not in r.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_runner_stops_cleanly_on_a_signal(sig):
    p = subprocess.Popen([sys.executable, "-c", RUNNER], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ))
    try:
        assert p.stdout.readline().strip() == "probe up"  # waits for the node, not for a fixed time
        p.send_signal(sig)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0 and "Traceback" not in err, err


FAILING = r'''
import sys
from hyst_common.node import run_node
from rclpy.node import Node

class Failing(Node):
    def __init__(self):
        super().__init__("failing")
        self.create_timer(0.01, self._boom)

    def _boom(self):
        raise ZeroDivisionError("callback bug")

def on_exit(node, by_signal):
    print(f"on_exit ran, by_signal={by_signal}", flush=True)

sys.exit(run_node(Failing, [sys.argv[0]], prog="failing_node", executor=sys.argv[1], on_exit=on_exit))
'''


@pytest.mark.parametrize("executor", ["events", "single"])
def test_runner_calls_on_exit_when_a_callback_raises(executor):
    """The driver ramps to its safe output in ``on_exit``: that must happen on a callback's error too, and the
    error must not be hidden (it is a bug: traceback, non-zero exit)."""
    r = subprocess.run([sys.executable, "-c", FAILING, executor], capture_output=True, text=True, timeout=120)
    assert "on_exit ran, by_signal=False" in r.stdout, (r.stdout, r.stderr)
    assert r.returncode != 0 and "callback bug" in r.stderr


FINISHING = r'''
import sys
from hyst_common.node import run_node
from rclpy.node import Node

class Done(Node):
    def __init__(self):
        super().__init__("done")

sys.exit(run_node(Done, [sys.argv[0]], prog="done_node", until=lambda n: True,
                  on_exit=lambda node, by_signal: int(sys.argv[1]) if sys.argv[1] != "none" else None))
'''


@pytest.mark.parametrize("code,expect", [("none", 0), ("0", 0), ("3", 3)])
def test_an_exit_code_on_exit_returns_is_the_processes(code, expect):
    """The driver returns 3 when its output was not confirmed at v_safe: exit 0 hid a device left at 100 V."""
    r = subprocess.run([sys.executable, "-c", FINISHING, code], capture_output=True, text=True, timeout=120)
    assert r.returncode == expect, r.stderr


class Amplitudes(AtomicParametersNode):
    def __init__(self, **kwargs) -> None:
        super().__init__("amplitudes", **kwargs)
        self.declare_parameter("amplitudes", [0.25, 0.5])


def test_whole_numbers_for_a_float_list_are_those_numbers(ctx):
    """``-p amplitudes:=[1]`` is an INTEGER_ARRAY to ROS and was refused at start, though a single whole number
    for a float parameter is taken."""
    node = Amplitudes(context=ctx, cli_args=["--ros-args", "-p", "amplitudes:=[1]"])
    try:
        p = node.get_parameter("amplitudes")
        assert list(p.value) == [1.0] and p.type_ == Parameter.Type.DOUBLE_ARRAY
        assert node.set_parameters([Parameter("amplitudes", value=[1, 2])])[0].successful
        assert list(node.get_parameter("amplitudes").value) == [1.0, 2.0]
        assert not node.set_parameters([Parameter("amplitudes", value=["a"])])[0].successful
    finally:
        node.destroy_node()


def test_diagnostics_carry_every_value_as_text_stamped_by_the_node(ctx):
    from diagnostic_msgs.msg import DiagnosticStatus

    from hyst_common.node import diagnostic_array, diagnostic_status
    node = Window(context=ctx)
    try:
        st = diagnostic_status("hyst_x", "stage", DiagnosticStatus.WARN, "degraded",
                               {"count": 3, "ratio": 1.0 / 3.0, "mode": "lockstep", "flag": True})
        assert (st.name, st.hardware_id, st.level, st.message) == ("hyst_x", "stage", DiagnosticStatus.WARN,
                                                                   "degraded")
        assert [(kv.key, kv.value) for kv in st.values] == [("count", "3"), ("ratio", "0.333333"),
                                                            ("mode", "lockstep"), ("flag", "True")]
        arr = diagnostic_array(node, [st, diagnostic_status("hyst_y", "stage", DiagnosticStatus.OK, "ok")])
        assert [s.name for s in arr.status] == ["hyst_x", "hyst_y"] and arr.status[1].values == []
        now = node.get_clock().now().nanoseconds
        stamp = arr.header.stamp.sec * 10**9 + arr.header.stamp.nanosec
        assert 0 < stamp <= now
    finally:
        node.destroy_node()
