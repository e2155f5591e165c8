"""hyst_residual_node in an isolated rclpy context: prediction/residual against the offline model, parameters."""
from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_model.core.params import pea_default
from hyst_model.io.params_file import spec_from_model, write_params
from hyst_model.model import MBWModel
from hyst_model.residual_node import ResidualNode
from hyst_model.spec import build_model

pytestmark = pytest.mark.ros
DT = 1e-3


class Rig:
    def __init__(self, params_file, **params):
        self.ctx = rclpy.Context()
        rclpy.init(args=["--ros-args", "--params-file", str(params_file)], context=self.ctx)
        self.node = ResidualNode(context=self.ctx,
                                 parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        self.tester = rclpy.create_node("tester", context=self.ctx)
        self.pred, self.res = [], []
        self.tester.create_subscription(JointState, "/model/prediction", self.pred.append, 1000)
        self.tester.create_subscription(JointState, "/model/residual", self.res.append, 1000)
        self.pub = self.tester.create_publisher(JointState, "/stage/state", 1000)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.tester)

    def spin_until(self, cond, timeout=10.0):
        end = time.monotonic() + timeout
        while not cond() and time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.01)
        return cond()

    def send(self, t, u, y=None):
        m = JointState()
        m.header.stamp = Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
        m.name = ["stage"]
        if u is not None:
            m.effort = [float(u)]
        if y is not None:
            m.position = [float(y)]
        self.pub.publish(m)

    def stream(self, t, u, y):
        n0 = self.node.counts["states"]
        for k in range(t.size):  # one at a time: the node's queue is a live-data KEEP_LAST queue
            self.send(t[k], u[k], y[k])
            assert self.spin_until(lambda: self.node.counts["states"] >= n0 + k + 1)

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.tester.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def rigs():
    made = []
    yield made
    for r in made:
        r.close()


def _mbw_params(tmp_path, offset=1e-6):
    p = pea_default()
    model = MBWModel(u_scale=p.u_scale, y_scale=p.y_scale)
    theta = model.pack({**p.to_dict(), "offset": offset})
    return model, theta, write_params(tmp_path / "mbw.yaml", spec_from_model(model, theta, dt=DT))


def _record(n=300):
    t = 100.0 + np.arange(n) * DT
    u = 75 - 60 * np.cos(2 * np.pi * 8.0 * (t - t[0]))
    return t, u


def _stamps(msgs):
    return np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in msgs])


def test_streams_the_mbw_model_exactly_and_stamps_like_the_state(tmp_path, rigs):
    model, theta, pf = _mbw_params(tmp_path)
    t, u = _record()
    y_off = model.simulate(theta, t, u)
    r_true = 3e-8 * np.sin(np.arange(t.size) / 7.0)
    rig = Rig(pf)
    rigs.append(rig)
    assert rig.node._settings.streaming
    rig.stream(t, u, y_off + r_true)
    assert rig.spin_until(lambda: len(rig.res) >= t.size)
    pred = np.array([m.position[0] for m in rig.pred])
    res = np.array([m.position[0] for m in rig.res])
    assert np.allclose(_stamps(rig.pred), t, atol=1e-9) and [m.name for m in rig.res[:1]] == [["stage"]]
    assert np.max(np.abs(pred - y_off)) < 1e-15 + 1e-12 * np.max(np.abs(y_off))
    assert np.max(np.abs(res - r_true)) < 1e-14


def test_composed_model_in_batches_matches_offline(tmp_path, rigs):
    cfg = {"u_scale": 15.0, "y_scale": 5.42e-6}
    model = build_model("mbw", ["dynamics"], cfg)
    theta = model.theta0.copy()
    theta[: 8] = pea_default().vector
    theta[-2:] = [60.0, 0.2]
    pf = write_params(tmp_path / "dyn.yaml", spec_from_model(model, theta, dt=DT))
    t, u = _record(250)
    y_off = model.simulate(theta, t, u)
    rig = Rig(pf, batch=50)
    rigs.append(rig)
    assert not rig.node._settings.streaming and rig.node._settings.model.name == "mbw+dynamics"
    rig.stream(t, u, y_off)
    assert rig.spin_until(lambda: len(rig.pred) >= 250)
    pred = np.array([m.position[0] for m in rig.pred])
    assert np.allclose(_stamps(rig.pred), t, atol=1e-9)
    assert np.max(np.abs(pred - y_off)) < 1e-12 * np.max(np.abs(y_off))


def test_parameters_validated_and_applied(tmp_path, rigs):
    model, theta, pf = _mbw_params(tmp_path)
    rig = Rig(pf)
    rigs.append(rig)
    n = rig.node
    r = n.set_parameters([Parameter("model.zeta1", value=float("nan"))])[0]
    assert not r.successful and "finite" in r.reason
    r = n.set_parameters([Parameter("model.base", value="nonsense")])[0]
    assert not r.successful and "nonsense" in r.reason
    assert not n.set_parameters([Parameter("reset_gap", value=-1.0)])[0].successful
    r = n.set_parameters([Parameter("model.zeta1", value=True)])[0]  # dynamically typed: a bool was taken
    assert not r.successful and "model.zeta1 must be a number" in r.reason
    # the configuration keys too: u_scale:=true became 1 and every state was then ignored as out of range
    for name, value, why in (("model.u_scale", True, "must be a number"), ("model.dt", "abc", "must be a number"),
                             ("model.dt", -1.0, "model.dt must be 0"), ("model.y_scale", 0.0, "must be positive")):
        r = n.set_parameters([Parameter(name, value=value)])[0]
        assert not r.successful and why in r.reason, (name, value, r.reason)
    # a diverging parameter set is refused with a reason
    r = n.set_parameters_atomically([Parameter("model.psi1", value=-0.5), Parameter("model.alpha1", value=-0.5)])
    assert not r.successful and "diverges" in r.reason
    # a new offset is applied: predictions shift by exactly that much
    t, u = _record(50)
    rig.stream(t, u, np.zeros(50))
    assert rig.spin_until(lambda: len(rig.pred) >= 50)
    first = np.array([m.position[0] for m in rig.pred[:50]])
    assert n.set_parameters([Parameter("model.offset", value=3e-6)])[0].successful
    rig.stream(t, u, np.zeros(50))  # same stamps again: a stamp going back restarts at rest anyway
    assert rig.spin_until(lambda: len(rig.pred) >= 100)
    second = np.array([m.position[0] for m in rig.pred[50:100]])
    assert np.allclose(second - first, 2e-6, atol=1e-15)


def test_bad_states_are_ignored_and_gaps_restart(tmp_path, rigs):
    model, theta, pf = _mbw_params(tmp_path)
    rig = Rig(pf, reset_gap=0.05)
    rigs.append(rig)
    t, u = _record(40)
    y = model.simulate(theta, t, u)
    rig.stream(t, u, y)
    rig.send(t[-1] + DT, None, 0.0)  # no effort
    rig.send(t[-1] + 2 * DT, float("nan"), 0.0)
    rig.send(t[-1] + 3 * DT, 1e4, 0.0)  # beyond twice the model's range: sent the prediction to -1 cm
    assert rig.spin_until(lambda: rig.node.counts["bad_states"] == 3)
    diags = []
    rig.tester.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    assert rig.spin_until(lambda: any(s.level == DiagnosticStatus.WARN and "3 state(s) ignored" in s.message
                                      for d in diags for s in d.status), timeout=30.0)
    rig.stream(t + 1.0, u, y)  # one second later: restart at rest -> the same predictions again
    assert rig.spin_until(lambda: len(rig.res) >= 80)
    res = np.array([m.position[0] for m in rig.res])
    assert rig.node.counts["resets"] == 1 and np.max(np.abs(res)) < 1e-14
    # a state without position still gets a prediction, but no residual
    rig.send(t[-1] + 1.001, 80.0)
    assert rig.spin_until(lambda: len(rig.pred) >= 81)
    rig.spin_until(lambda: False, timeout=0.1)
    assert len(rig.res) == 80
    # a corrupt reading (1e300 m) was published as a 1e300 m residual at level OK: predicted, not compared
    rig.send(t[-1] + 1.002, 80.0, 1e300)
    assert rig.spin_until(lambda: len(rig.pred) >= 82 and rig.node.counts["bad_readings"] == 1)
    assert rig.spin_until(lambda: any(s.level == DiagnosticStatus.WARN and "1 reading(s) not compared" in s.message
                                      for d in diags for s in d.status), timeout=30.0)
    assert len(rig.res) == 80


def test_without_a_params_file_the_node_refuses_to_start():
    """The default model speaks model units (1 V, 1 m per unit): it predicted 120 m at 75 V."""
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).parent / "hyst_residual_node"
    p = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "--params-file" in err[0], p.stderr
