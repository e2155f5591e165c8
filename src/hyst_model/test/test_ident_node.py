"""hyst_ident_node in an isolated context: fits queued and watched bags, writes the params file, pushes the model
to a (fake) controller through its parameter service, validates its own parameters, survives bad bags."""
import json
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rcl_interfaces.msg import SetParametersResult  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from hyst_model.core import PARAM_NAMES, pea_default  # noqa: E402
from hyst_model.ident_node import IdentNode  # noqa: E402
from hyst_model.io import read_params, write_state_bag  # noqa: E402

pytestmark = pytest.mark.ros
TRUE = pea_default().replace(offset=-1.0e-6)
KEYS = PARAM_NAMES + ("offset", "u_scale", "y_scale")


def _bag(path, seed=0, n=2000):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 5e-4
    u = 75 + 50 * np.sin(2 * np.pi * 3 * t) + 15 * np.sin(2 * np.pi * 11 * t)
    return write_state_bag(path, t, u, TRUE.simulate(u) + rng.normal(0, 2e-9, n))


class FakeController(Node):
    """Declares model.* like hyst_control's controller node and rejects a non-MBW base."""

    def __init__(self, context):
        super().__init__("fake_ctrl", context=context)
        self.declare_parameter("model.base", "mbw")
        self.declare_parameter("model.dt", 0.0)
        for k in KEYS:
            self.declare_parameter(f"model.{k}", 0.0)
        self.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, params):
        for p in params:
            if p.name == "model.base" and p.value != "mbw":
                return SetParametersResult(successful=False, reason="need mbw")
        return SetParametersResult(successful=True)


def _spin_until(ex, cond, timeout=60.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        ex.spin_once(timeout_sec=0.05)
    return cond()


def test_fits_bag_writes_params_and_pushes_to_controller(tmp_path, ctx):
    bag = _bag(tmp_path / "run1")
    out = tmp_path / "model.yaml"
    ctrl = FakeController(ctx)
    node = IdentNode(context=ctx, parameter_overrides=[
        Parameter("bags", Parameter.Type.STRING_ARRAY, [str(bag)]),
        Parameter("params_file", Parameter.Type.STRING, str(out)),
        Parameter("controller_node", Parameter.Type.STRING, "/fake_ctrl")])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(ctrl)
    ex.add_node(node)
    try:
        assert _spin_until(ex, lambda: any(r.get("push") == "accepted" for r in node.results))
        fit = next(r for r in node.results if "rmse" in r)
        assert fit["rmse"] < 5e-9 and fit["params_file"] == str(out)
        spec = read_params(out)
        for k in KEYS:
            v = spec.values.get(k, spec.config.get(k))
            assert ctrl.get_parameter(f"model.{k}").value == pytest.approx(v, rel=1e-12, abs=1e-300)
        g = lambda k: ctrl.get_parameter(f"model.{k}").value  # noqa: E731
        assert g("dt") == pytest.approx(5e-4, rel=1e-9)  # the sample period travels with the model
        # the small-signal gain ζ1·y_scale/u_scale (m/V) is scale-free and must match the truth
        assert g("zeta1") * g("y_scale") / g("u_scale") == pytest.approx(TRUE.zeta1 * TRUE.y_scale / TRUE.u_scale,
                                                                         rel=0.01)
        # parameters are validated: a bad method is rejected with a reason, a good change is applied
        r = node.set_parameters([Parameter("method", Parameter.Type.STRING, "magic")])[0]
        assert not r.successful and "method" in r.reason
        r = node.set_parameters([Parameter("watch_dir", Parameter.Type.STRING, str(tmp_path / "nope"))])[0]
        assert not r.successful
    finally:
        ex.shutdown()
        node.destroy_node()
        ctrl.destroy_node()


def test_watched_folder_bad_bag_survives_and_params_file_is_protected(tmp_path, ctx):
    watch = tmp_path / "incoming"
    watch.mkdir()
    out = tmp_path / "model.yaml"
    out.write_text("user's own file\n")
    node = IdentNode(context=ctx, parameter_overrides=[
        Parameter("watch_dir", Parameter.Type.STRING, str(watch)),
        Parameter("poll_period", Parameter.Type.DOUBLE, 0.1),
        Parameter("settle_time", Parameter.Type.DOUBLE, 0.2),
        Parameter("params_file", Parameter.Type.STRING, str(out))])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    received = []
    sub_node = Node("listener", context=ctx)
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String
    sub_node.create_subscription(String, "/hyst_ident_node/fit_result", lambda m: received.append(json.loads(m.data)),
                                 QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    ex.add_node(sub_node)
    try:
        ex.spin_once(timeout_sec=0.1)
        bad = watch / "broken.mcap"
        bad.write_bytes(b"\x89MCAP0\r\n garbage")
        _bag(watch / "good")
        assert _spin_until(ex, lambda: len(received) >= 2)
        by_bag = {r["bag"].rsplit("/", 1)[-1]: r for r in received}
        assert "error" in by_bag["broken.mcap"]
        assert by_bag["good"]["rmse"] < 5e-9
        assert "exists" in by_bag["good"]["params_file_error"]  # existing user file is not replaced ...
        assert out.read_text() == "user's own file\n"
        assert node.set_parameters([Parameter("overwrite", Parameter.Type.BOOL, True)])[0].successful
        _bag(watch / "good2", seed=1)  # ... unless overwrite is set
        assert _spin_until(ex, lambda: any(r["bag"].endswith("good2") for r in received))
        assert read_params(out).base == "mbw"
    finally:
        ex.shutdown()
        node.destroy_node()
        sub_node.destroy_node()


def test_params_file_loads_through_ros_params_file(tmp_path, ctx):
    """The params file is a valid ROS 2 parameters file: rcl parses it for --params-file."""
    _ = ctx
    from hyst_model.io import spec_from_model, write_params
    from hyst_model.models import BASE_MODELS
    m = BASE_MODELS["mbw"]({"u_scale": 15.0, "y_scale": 5.42e-6})
    p = write_params(tmp_path / "p.yaml", spec_from_model(m, m.theta0, fit={"method": "fast", "rmse": 1e-8},
                                                           dt=5e-4))
    c = Context()
    rclpy.init(args=["--ros-args", "--params-file", str(p)], context=c)
    try:
        n = Node("any_name", context=c, automatically_declare_parameters_from_overrides=True)
        assert n.get_parameter("model.base").value == "mbw"
        assert n.get_parameter("model.zeta1").value == pytest.approx(0.4)
        assert n.get_parameter("model.dt").value == pytest.approx(5e-4)
        n.destroy_node()
    finally:
        rclpy.try_shutdown(context=c)


def _irregular_bag(path, kind, n=2400):
    """A lockstep bag (sample 0 re-announced 3 times) or a realtime bag with missed periods."""
    rng = np.random.default_rng(4)
    t = np.arange(n) * 5e-4
    u = 75 + 50 * np.sin(2 * np.pi * 3 * t) + 15 * np.sin(2 * np.pi * 11 * t)
    y = TRUE.simulate(u) + rng.normal(0, 2e-9, n)
    if kind == "lockstep":
        idx = np.r_[[0, 0, 0], np.arange(n)]
    else:  # two missed stretches of 3 periods and one of 200
        keep = np.ones(n, bool)
        keep[[500, 501, 502, 900, 901, 902]] = False
        keep[1500:1700] = False
        idx = np.flatnonzero(keep)
    return write_state_bag(path, t[idx], u[idx], y[idx])


@pytest.mark.parametrize("kind,gaps,ok", [("lockstep", "refuse", True), ("gappy", "auto", True),
                                          ("gappy", "bridge", None), ("gappy", "refuse", False)])
def test_lockstep_and_gappy_bags_are_regularised_as_the_gaps_parameter_says(tmp_path, ctx, kind, gaps, ok):
    bag = _irregular_bag(tmp_path / kind, kind)
    node = IdentNode(context=ctx, parameter_overrides=[
        Parameter("bags", Parameter.Type.STRING_ARRAY, [str(bag)]),
        Parameter("gaps", Parameter.Type.STRING, gaps)])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        assert _spin_until(ex, lambda: len(node.results) >= 1)
        r = node.results[0]
        if ok:
            assert r["rmse"] < 5e-9 and r["dt"] == pytest.approx(5e-4) and r["notes"], r
        elif ok is None:  # bridging the 200-period gap holds u and interpolates y: it runs and says so
            assert any("bridged 3 gap" in n for n in r["notes"]), r
        else:
            assert "error" in r and "gap" in r["error"].lower(), r
        assert not node.set_parameters([Parameter("gaps", Parameter.Type.STRING, "magic")])[0].successful
    finally:
        ex.shutdown()
        node.destroy_node()


def test_bad_start_parameter_is_one_line_and_exit_2(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path
    exe = str(Path(sys.executable).parent / "hyst_ident_node")
    for bad in ("watch_dir:=/nope", "gaps:=sometimes", "poll_period:=-1.0"):
        p = subprocess.run([exe, "--ros-args", "-p", bad], capture_output=True, text=True, timeout=120,
                           env=dict(os.environ))
        assert p.returncode == 2, (bad, p.returncode, p.stderr)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in p.stderr and lines[0].startswith("hyst_ident_node"), p.stderr
