"""hyst_sim_node in isolated rclpy contexts: lockstep determinism, clipping, timeout, parameters, hidden scenario."""
import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_sim.plant import Plant
from hyst_sim.scenario import scenario_dir
from hyst_sim.sim_node import SimNode, plant_config

pytestmark = pytest.mark.ros


class Rig:
    """A SimNode plus a tester node in their own context and executor."""

    def __init__(self, **params):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = SimNode(context=self.ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        self.tester = rclpy.create_node("tester", context=self.ctx)
        self.states, self.diags = [], []
        self.tester.create_subscription(JointState, "/stage/state", self.states.append, 100)
        self.tester.create_subscription(DiagnosticArray, "/diagnostics", self.diags.append, 10)
        self.cmd = self.tester.create_publisher(JointState, "/stage/command", 10)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.tester)

    def spin_until(self, cond, timeout=10.0):
        end = time.monotonic() + timeout
        while not cond() and time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.01)
        return cond()

    def send(self, v, stamp=None):
        m = JointState()
        if stamp is not None:
            m.header.stamp = stamp
        m.name = ["stage"]
        m.effort = [float(v)]
        self.cmd.publish(m)

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.tester.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def rig_factory():
    rigs = []

    def make(**params):
        rigs.append(Rig(**params))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def _lockstep_run(make, n, **params):
    rig = make(mode="lockstep", **params)
    assert rig.spin_until(lambda: len(rig.states) >= 1), "no initial state in lockstep"
    cmds = 60.0 + 50.0 * np.sin(2 * np.pi * np.arange(n) / 40.0)
    cmds[5] = np.nan
    cmds[9] = 250.0  # clipped (beyond v_max by less than the span; more is rejected as the driver does)
    for k in range(n):
        last = rig.states[-1]
        rig.send(cmds[k], last.header.stamp)
        rig.send(cmds[k], last.header.stamp)                   # a duplicate answer must not take a sample
        assert rig.spin_until(lambda: len(rig.states) > k + 1 and
                              rig.states[-1].header.stamp != last.header.stamp), f"no state for command {k}"
    rig.spin_until(lambda: False, 0.2)
    uniq = {}
    for m in rig.states:                                       # sample 0 may have been announced twice
        uniq[(m.header.stamp.sec, m.header.stamp.nanosec)] = m
    msgs = [uniq[k] for k in sorted(uniq)]
    return rig, cmds, msgs


def test_lockstep_is_deterministic_and_equals_the_offline_plant(rig_factory):
    n = 120
    rig, cmds, a = _lockstep_run(rig_factory, n, seed=5, rate=2000.0)
    assert len(a) == n + 1
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in a]
    np.testing.assert_allclose(np.diff(stamps), 5e-4, rtol=0, atol=1e-9)
    assert a[0].name == ["stage"] and a[0].header.frame_id == "stage"
    y = np.array([m.position[0] for m in a])
    u = np.array([m.effort[0] for m in a])
    offline = Plant(plant_config(rig.node._settings)).run(np.concatenate([[0.0], cmds]))
    np.testing.assert_array_equal(y, offline.y)                # bit for bit, noise included
    np.testing.assert_array_equal(u, offline.u_applied)
    assert u[6] == u[5] and u[10] == 150.0                     # NaN held, 250 V clipped
    assert rig.node.counts["stale"] >= n and rig.node.counts["nonfinite"] == 1
    rig.close()
    _, _, b = _lockstep_run(rig_factory, n, seed=5, rate=2000.0)
    np.testing.assert_array_equal(y, [m.position[0] for m in b])


def test_realtime_clips_reports_and_ramps_to_safe_after_timeout(rig_factory):
    rig = rig_factory(rate=500.0, command_timeout=0.15, safe_ramp_rate=1000.0, slew_max=2000.0, v_safe=0.0)
    assert rig.spin_until(lambda: len(rig.states) > 5)
    assert all(m.effort[0] == 0.0 for m in rig.states)         # rests at v_safe before any command
    # keep commanding 250 V until the stage sits at the clip (clipped; 500 V, more than the span beyond 150 V,
    # is rejected as the driver does), however slowly a loaded machine runs the sim
    t_end = time.monotonic() + 60.0
    while rig.states[-1].effort[0] != 150.0 and time.monotonic() < t_end:
        rig.send(250.0)
        rig.spin_until(lambda: False, 0.02)
    efforts = [m.effort[0] for m in rig.states]
    assert max(efforts) == 150.0 and all(0.0 <= e <= 150.0 for e in efforts)
    assert np.all(np.diff(efforts) <= 2000.0 / 500.0 + 1e-9)  # slew limit per sample
    assert rig.spin_until(lambda: any("clipping" in s.message and s.level == b"\x01"
                                      for d in rig.diags for s in d.status), 3.0)
    n0 = len(rig.states)
    assert rig.spin_until(lambda: rig.states[-1].effort[0] == 0.0, 3.0)   # timeout → ramp down to v_safe
    down = [m.effort[0] for m in rig.states[n0:]]
    assert np.all(np.diff(down) >= -1000.0 / 500.0 - 1e-9)   # ramped, not jumped
    assert rig.spin_until(lambda: any("timeout" in s.message for d in rig.diags for s in d.status), 3.0)
    rig.send(float("nan"))
    assert rig.spin_until(lambda: rig.node.counts["nonfinite"] > 0, 2.0)
    assert rig.states[-1].effort[0] == 0.0


def test_parameters_are_validated_with_a_reason_and_applied_live(rig_factory):
    rig = rig_factory(rate=200.0)
    node = rig.node
    bad = [
        [Parameter("v_max", value=100.0), Parameter("v_min", value=120.0)],
        [Parameter("profile", value="gma")],                   # 0-150 V does not fit +-5 V
        [Parameter("profile", value="xyz")],
        [Parameter("v_safe", value=149.0), Parameter("v_max", value=100.0)],
        [Parameter("effects.creep", value=5.0)],               # outside the declared range
        [Parameter("scenario_file", value="/nonexistent/s.yaml")],
        [Parameter("params_file", value="/nonexistent/p.yaml")],
        [Parameter("mode", value="lockstep")],                 # read-only
    ]
    for params in bad:
        res = node.set_parameters_atomically(params)
        assert not res.successful and res.reason, params
    assert node.get_parameter("v_max").value == 150.0
    ok = node.set_parameters_atomically([Parameter("profile", value="gma"), Parameter("v_min", value=-5.0),
                                         Parameter("v_max", value=5.0)])
    assert ok.successful
    assert rig.spin_until(lambda: len(rig.states) > 3)
    rig.send(-9.0)
    assert rig.spin_until(lambda: rig.states[-1].effort[0] == -5.0, 3.0)
    assert node.set_parameters([Parameter("effects.delay", value=3)])[0].successful
    assert node._plant.config.effects.delay.strength == 3
    assert node.set_parameters([Parameter("rate", value=400.0)])[0].successful
    assert node._plant.dt == pytest.approx(1 / 400.0)


def test_hidden_scenario_is_applied_but_never_echoed(rig_factory, tmp_path, capfd):
    src = (scenario_dir() / "hidden_creep_delay.yaml").read_text()
    path = tmp_path / "scenario.yaml"
    path.write_text(src)
    rig = rig_factory(mode="lockstep", scenario_file=str(path))
    assert rig.node._plant.config.effects.delay.strength == 2    # applied inside the plant
    assert rig.spin_until(lambda: len(rig.states) >= 1)
    for k in range(30):
        rig.send(100.0, rig.states[-1].header.stamp)
        n = len(rig.states)
        assert rig.spin_until(lambda: len(rig.states) > n, 30.0)  # lockstep: each answer gives a state
    assert rig.spin_until(lambda: len(rig.diags) > 0, 30.0)       # so "never echoed" is checked on diagnostics
    visible = {p.name: p.value for p in rig.node._parameters.values()}
    assert visible["effects.creep"] == 0.0 and visible["effects.delay"] == 0
    text = capfd.readouterr()
    blob = " ".join([text.out, text.err] + [f"{s.message} {s.values}" for d in rig.diags for s in d.status]
                    + [str(m) for m in rig.states[:3]])
    assert "scenario loaded" in blob                               # the log is captured, so the check bites
    for secret in ("creep", "delay", "0.01", "tau"):
        assert secret not in blob.replace("effects.", "")
    y = [m.position[0] for m in rig.states]
    assert max(abs(v) for v in y[1:3]) < 50e-9                  # the delay shows in the data only
    assert not math.isnan(y[-1])


@pytest.mark.slow
def test_console_script_exits_cleanly_on_sigterm_and_refuses_bad_parameters():
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    exe = str(Path(sys.executable).with_name("hyst_sim_node"))
    helped = subprocess.run([exe, "--help"], capture_output=True, timeout=60)
    assert helped.returncode == 0 and b"effects.creep" in helped.stdout
    bad = subprocess.run([exe, "--ros-args", "-p", "rate:=0.0"], capture_output=True, timeout=60)
    assert bad.returncode == 2 and b"rate" in bad.stderr and b"Traceback" not in bad.stderr
    bad = subprocess.run([exe, "--ros-args", "-p", "v_min:=-3.0"], capture_output=True, timeout=60)
    assert bad.returncode == 2 and b"v_min" in bad.stderr and b"Traceback" not in bad.stderr
    proc = subprocess.Popen([exe, "--ros-args", "-p", "rate:=500.0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("probe", context=ctx)
    got = []
    node.create_subscription(JointState, "/stage/state", got.append, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        end = time.monotonic() + 20.0
        while len(got) < 50 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)      # a hang here was a real bug (EventsExecutor ignores SIGTERM)
    finally:
        if proc.poll() is None:
            proc.kill()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert len(got) >= 50 and got[-1].name == ["stage"]
    assert proc.returncode == 0, err.decode(errors="replace")[-3000:]



def _set_via_service(rig, params):
    """``params`` through the node's real ``set_parameters`` service (what ``ros2 param set`` and rqt call)."""
    from rcl_interfaces.srv import SetParameters
    cli = rig.tester.create_client(SetParameters, "/hyst_sim/set_parameters")
    assert rig.spin_until(cli.service_is_ready, 30.0), "set_parameters service not up"
    fut = cli.call_async(SetParameters.Request(parameters=[p.to_parameter_msg() for p in params]))
    assert rig.spin_until(fut.done, 30.0), "no set_parameters response"
    rig.tester.destroy_client(cli)
    return fut.result().results


@pytest.mark.parametrize("via", ["service", "local"])
def test_parameter_sets_are_all_or_nothing(rig_factory, via):
    """Issue 13: set_parameters([v_min=100, v_max=50]) applied v_max; a rejected profile change left v_max = 5 V."""
    rig = rig_factory(rate=200.0)
    node = rig.node
    apply = (lambda ps: _set_via_service(rig, ps)) if via == "service" else node.set_parameters

    def limits():
        return (node.get_parameter("profile").value, node.get_parameter("v_min").value,
                node.get_parameter("v_max").value, node._settings.v_min, node._settings.v_max,
                node._plant.config.v_min, node._plant.config.v_max)

    before = limits()
    assert before == ("pea", 0.0, 150.0, 0.0, 150.0, 0.0, 150.0)
    # inconsistent together (rclpy's own service refused v_min alone and applied v_max = 50 V)
    res = apply([Parameter("v_min", value=100.0), Parameter("v_max", value=50.0)])
    assert len(res) == 2 and not any(r.successful for r in res) and all("v_min" in r.reason for r in res)
    assert limits() == before
    # the profile alone is refused while 0-150 V stays; with a v_max that does not fit gma either, nothing moves
    res = apply([Parameter("profile", value="gma"), Parameter("v_max", value=7.0)])
    assert len(res) == 2 and not any(r.successful for r in res) and res[0].reason
    assert limits() == before
    one_undeclared = [Parameter("v_min", value=100.0), Parameter("nope", value=1.0)]   # none applied
    if via == "service":
        res = apply(one_undeclared)
        assert len(res) == 2 and not any(r.successful for r in res) and "nope" in res[0].reason
    else:  # rclpy's local API raises for an undeclared name
        from rclpy.exceptions import ParameterNotDeclaredException
        with pytest.raises(ParameterNotDeclaredException):
            apply(one_undeclared)
    assert limits() == before
    res = apply([Parameter("v_min", value=10.0), Parameter("v_max", value=120.0), Parameter("v_safe", value=10.0)])
    assert len(res) == 3 and all(r.successful for r in res)
    assert limits() == ("pea", 10.0, 120.0, 10.0, 120.0, 10.0, 120.0)
    res = apply([Parameter("profile", value="gma"), Parameter("v_min", value=-5.0), Parameter("v_max", value=5.0),
                 Parameter("v_safe", value=0.0)])
    assert all(r.successful for r in res) and limits() == ("gma", -5.0, 5.0, -5.0, 5.0, -5.0, 5.0)


def _status(rig, cond, timeout=15.0, name="hyst_sim: stage"):
    found = []

    def check():
        for a in rig.diags:
            for st in a.status:
                if st.name == name and cond(st):
                    found.append(st)
        rig.diags.clear()
        return bool(found)
    assert rig.spin_until(check, timeout), "no matching /diagnostics status"
    return found[0]


def _values(st):
    return {kv.key: kv.value for kv in st.values}


def test_missed_realtime_periods_are_reported_with_their_share(rig_factory):
    rig = rig_factory(rate=1000.0)
    assert rig.spin_until(lambda: len(rig.states) > 5)
    with rig.node._lock:  # stall the sampler for 0.3 s (the test of a late thread, not a wait): ~300 periods
        before = rig.node.counts["late_ticks"]
        time.sleep(0.3)
    # all ~300 are counted at once when the sampler wakes, so they land in one diagnostics period
    st = _status(rig, lambda s: int(_values(s)["missed_periods"]) >= before + 250, name="hyst_sim: timing")
    vals = _values(st)
    share = float(vals["missed_share"])
    assert 0.1 < share < 1.0 and st.level == st.ERROR
    pct = float(st.message.split("missed periods (")[1].split(" %")[0])
    assert abs(pct - 100 * share) <= 0.51, (pct, share)           # the same share in the message, rounded
    # the missed samples are not published in a burst: the stream has a gap, the stamps stay increasing
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in rig.states])
    assert np.all(np.diff(stamps) > 0) and np.diff(stamps).max() > 0.2


def test_end_stop_is_a_fault_on_diagnostics_not_a_number(rig_factory):
    rig = rig_factory(mode="lockstep", slew_max=1e7, rate=2000.0)
    assert rig.spin_until(lambda: len(rig.states) >= 1), "no initial state in lockstep"
    for k in range(80):
        last = rig.states[-1]
        rig.send(150.0 if k % 2 == 0 else 0.0, last.header.stamp)
        assert rig.spin_until(lambda: rig.states[-1].header.stamp != last.header.stamp), f"no state for {k}"
    y = np.array([m.position[0] for m in rig.states])
    assert np.all(np.isfinite(y)) and y.min() > -20e-6 and y.max() < 50e-6
    assert rig.node.counts["end_stop"] > 0
    assert rig.spin_until(lambda: any(s.level == b"\x02" and "end stop" in s.message
                                      for d in rig.diags for s in d.status), 5.0)


def test_end_stop_fault_names_its_samples_and_clears_when_the_stage_is_free(rig_factory):
    rig = rig_factory(mode="lockstep", slew_max=1e7, rate=2000.0)
    assert rig.spin_until(lambda: len(rig.states) >= 1), "no initial state in lockstep"
    for k in range(40):
        last = rig.states[-1]
        rig.send(150.0 * (k % 2 == 0), last.header.stamp)
        assert rig.spin_until(lambda: rig.states[-1].header.stamp != last.header.stamp), f"no state for {k}"
    n_stop = rig.node.counts["end_stop"]
    assert n_stop > 0
    st = _status(rig, lambda s: s.level == s.ERROR)
    assert "FAULT" in st.message and 0 < int(_values(st)["end_stop_samples"]) <= n_stop  # a second may split the run
    for k in range(40):  # a calm input: the stage leaves the stop
        last = rig.states[-1]
        rig.send(75.0, last.header.stamp)
        assert rig.spin_until(lambda: rig.states[-1].header.stamp != last.header.stamp), f"no state for {k}"
    # a later second without stop contact is no longer a fault; the total stays on record
    ok = _status(rig, lambda s: s.level != s.ERROR, timeout=30.0)
    assert "end stop" not in ok.message and int(_values(ok)["end_stop_samples"]) >= n_stop



def test_a_custom_stage_runs_its_own_range_and_equals_the_offline_plant(rig_factory, ten_volt_stage):
    """profile custom: a ±10 V stage from its params file; ±9 V applied as sent (beyond the GMA's ±5 V), 20 V
    clipped to its 10 V, bit for bit the offline plant."""
    rig = rig_factory(mode="lockstep", profile="custom", params_file=ten_volt_stage, v_min=-10.0,
                      v_max=10.0, seed=3)
    assert rig.spin_until(lambda: len(rig.states) >= 1), "no initial state in lockstep"
    assert rig.node._settings.v_safe == 0.0 and rig.node._settings.slew_max == 20.0 / 1e-3
    cmds = 9.0 * np.sin(2 * np.pi * np.arange(40) / 40.0)
    cmds[30] = 20.0
    for k, c in enumerate(cmds):
        last = rig.states[-1]
        rig.send(c, last.header.stamp)
        assert rig.spin_until(lambda: rig.states[-1].header.stamp != last.header.stamp), f"no state for {k}"
    uniq = {(m.header.stamp.sec, m.header.stamp.nanosec): m for m in rig.states}
    msgs = [uniq[k] for k in sorted(uniq)]
    u = np.array([m.effort[0] for m in msgs])
    offline = Plant(plant_config(rig.node._settings)).run(np.concatenate([[0.0], cmds]))
    np.testing.assert_array_equal([m.position[0] for m in msgs], offline.y)
    assert u[10] == cmds[9] and u.min() < -8.8 and u[31] == 10.0


@pytest.mark.parametrize("params,why", [
    (dict(profile="custom", v_min=-10.0, v_max=10.0), "needs params_file"),
    (dict(profile="custom", params_file="STAGE"), "needs v_min and v_max"),
])
def test_a_custom_stage_without_its_model_or_range_is_refused_with_the_reason(ten_volt_stage, params, why):
    params = {k: (ten_volt_stage if v == "STAGE" else v) for k, v in params.items()}
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        with pytest.raises(Exception, match=why):
            SimNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_huge_command_is_rejected_and_held_as_the_driver_does(rig_factory):
    """1e300 V (or 150000 meant as mV) was applied as full scale; as the driver's limiter, a command more than the
    range's span outside it holds the last voltage and is counted; one just outside is clipped as before."""
    rig = rig_factory(mode="lockstep", seed=1)
    assert rig.spin_until(lambda: len(rig.states) >= 1), "no initial state in lockstep"
    for k, c in enumerate((50.0, 1e300, 150000.0, -1e6, 200.0)):
        last = rig.states[-1]
        rig.send(c, last.header.stamp)
        assert rig.spin_until(lambda: rig.states[-1].header.stamp != last.header.stamp), f"no state for {k}"
    u = [m.effort[0] for m in rig.states[-5:]]
    assert u[:4] == [50.0, 50.0, 50.0, 50.0] and u[4] == 150.0
    assert rig.node._counts["rejected"] == 3 and rig.node._counts["clip_range"] == 1


def test_realtime_samples_are_stamped_on_their_schedule_whole_periods_apart(rig_factory):
    """Stamped with the moment the thread got to them, a loaded machine's samples jittered and read as missed
    periods (a realtime bag of an effect-free stage fitted at 76 nm, 2 nm in lockstep); on the schedule every
    interval is a whole number of periods, and a real miss stays one."""
    rig = rig_factory(rate=500.0)
    assert rig.spin_until(lambda: len(rig.states) > 200, 60.0)
    ns = np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in rig.states[:200]])
    k = np.diff(ns) / 2_000_000  # in periods of 2 ms, exact in integer nanoseconds
    assert np.all(np.abs(k - np.round(k)) < 1e-6) and np.all(np.round(k) >= 1), k


def test_a_model_fitted_on_a_clock_a_few_ppm_off_runs_at_the_loop_rate():
    """The median period of a real stage's stamps carries its clock's error: 1.00002 ms was refused at 1 kHz."""
    from hyst_sim.errors import ConfigError
    from hyst_sim.plant_config import substeps_for

    assert substeps_for(1e-3, 1.00002e-3) == 1 and substeps_for(2e-3, 1.000656e-3) == 2
    with pytest.raises(ConfigError, match="integer multiple"):
        substeps_for(1e-3, 1.01e-3)
