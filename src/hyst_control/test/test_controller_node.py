"""Controller node in an isolated context: stamps echoed, parameters validated with reasons, params file and
run-time model updates, watchdog."""
from __future__ import annotations

import math
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_control.controller_node import ControllerNode

pytestmark = pytest.mark.ros


@pytest.fixture
def harness(tmp_path):
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    made = []

    def make(*cli):
        node = ControllerNode(context=ctx, cli_args=["--ros-args", *cli] if cli else None)
        peer = rclpy.create_node("peer", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(peer)
        got = {"cmd": [], "diag": [], "cstate": []}
        peer.create_subscription(JointState, "/stage/command", got["cmd"].append, 100)
        peer.create_subscription(JointState, "/controller/state", got["cstate"].append, 100)
        peer.create_subscription(DiagnosticArray, "/diagnostics", got["diag"].append, 100)
        pub = peer.create_publisher(JointState, "/stage/state", 100)
        made.extend([node, peer])
        return node, peer, ex, pub, got

    yield make
    for n in made:
        n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _state(k: int, y: float, u: float) -> JointState:
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = 100 + k // 1000, (k % 1000) * 1_000_000
    m.name, m.position, m.effort = ["stage"], [y], [u]
    return m


def _spin_until(ex, cond, timeout=10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        ex.spin_once(timeout_sec=0.01)
    return cond()


def test_commands_echo_the_state_stamp_and_publish_internal_state(harness):
    node, peer, ex, pub, got = harness("-p", "state_decimation:=1", "-p", "reference:=constant:15",
                                       "-p", "watchdog_periods:=100000")
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    for k in range(20):
        pub.publish(_state(k, 10e-6, 50.0))
        assert _spin_until(ex, lambda: len(got["cmd"]) > k)
    stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in got["cmd"]]
    assert stamps == [(100, k * 1_000_000) for k in range(20)]
    assert all(0.0 <= m.effort[0] <= 150.0 for m in got["cmd"])
    assert got["cmd"][0].effort[0] > 50.0  # 5 µm below the reference: DPPC pushes up
    names = got["cstate"][-1].name
    assert {"error", "epsilon", "lambda", "nu"} <= set(names)


@pytest.mark.parametrize(("name", "value", "why"), [
    ("algorithm", "lqr", "algorithm must be one of"),
    ("dppc.lambda_inf", 30e-6, "lambda0 > lambda_inf"),
    ("dmrac.initial", "cs7", "dmrac.initial"),
    ("model.delta1", 1.2, "delta1"),
    ("v_min", 160.0, "v_min"),
    ("model.dt", 0.0005, "set rate:=2000"),
])
def test_bad_parameters_are_rejected_with_a_reason(harness, name, value, why):
    node, *_ = harness()
    res = node.set_parameters([Parameter(name, value=value)])[0]
    assert not res.successful and why in res.reason
    assert node.get_parameter(name).value != value


def test_out_of_range_gain_is_rejected_by_the_descriptor(harness):
    node, *_ = harness()
    res = node.set_parameters([Parameter("dppc.chi", value=1.5)])[0]
    assert not res.successful


def test_params_file_sets_the_model_and_model_updates_apply_at_run_time(harness, tmp_path):
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: []\n      zeta1: 0.45\n"
                 "      y_scale: 5.0e-06\n      dt: 0.001\n    fit:\n      method: fast\n      rmse: 1.0e-08\n")
    node, peer, ex, pub, got = harness("--params-file", str(p), "-p", "algorithm:=dmrac")
    assert node.get_parameter("model.zeta1").value == pytest.approx(0.45)
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    pub.publish(_state(0, 10e-6, 50.0))
    assert _spin_until(ex, lambda: len(got["cmd"]) > 0)
    assert node._ctrl.model.zeta1 == pytest.approx(0.45)
    assert node.set_parameters([Parameter("model.delta2", value=0.95)])[0].successful
    assert node._ctrl.model.delta2 == pytest.approx(0.95)


def test_watchdog_commands_v_safe_and_reports_error(harness):
    node, peer, ex, pub, got = harness("-p", "rate:=1000.0", "-p", "watchdog_periods:=20", "-p", "v_safe:=5.0")
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    for k in range(5):
        pub.publish(_state(k, 15e-6, 80.0))
        _spin_until(ex, lambda: len(got["cmd"]) > k)
    assert _spin_until(ex, lambda: any(m.effort[0] <= 5.0 + 1e-9 for m in got["cmd"]), timeout=5.0)
    assert node.counts["watchdog_trips"] == 1
    assert _spin_until(ex, lambda: any(s.level == DiagnosticStatus.ERROR for d in got["diag"] for s in d.status),
                       timeout=5.0)
    # states come back: the controller restarts from the applied voltage, no jump
    n0 = len(got["cmd"])
    pub.publish(_state(100, 15e-6, 5.0))
    assert _spin_until(ex, lambda: len(got["cmd"]) > n0)
    assert math.isfinite(got["cmd"][-1].effort[0])
    assert not node._tripped


def test_effects_of_a_params_file_are_compensated_or_reported_never_silently_dropped(harness, tmp_path):
    """Creep and delay have inverses, drift an observer (compensated; open loop cannot use the observer, said);
    an unknown effect's keys are named on /diagnostics."""
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: [creep, delay, drift]\n"
                 "      zeta1: 0.45\n      y_scale: 5.0e-06\n      dt: 0.001\n"
                 "      creep:\n        gain: 0.01\n        tilt: 0.0\n      delay:\n        tau: 0.002\n"
                 "      drift:\n        c1: 1.0e-8\n      hum:\n        amp: 1.0e-9\n")
    node, peer, ex, pub, got = harness("--params-file", str(p))
    assert node._compensating == ["creep", "delay", "drift"]
    assert "open_loop does not compensate drift" in node._unused and "model.hum.amp" in node._unused
    assert "creep" not in node._unused
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    for k in range(3):
        pub.publish(_state(k, 10e-6, 50.0))
        assert _spin_until(ex, lambda: len(got["cmd"]) > k)
    assert math.isfinite(got["cmd"][-1].effort[0])
    assert getattr(node._ctrl, "preview", 0.0) == pytest.approx(0.002)  # the delay's preview

    def warned() -> bool:
        return any(s.level >= DiagnosticStatus.WARN and "open_loop does not compensate drift" in s.message
                   and any(v.key == "compensated" and v.value == "creep,delay,drift" for v in s.values)
                   for d in got["diag"] for s in d.status)

    assert _spin_until(ex, warned, 5.0)
    plain = tmp_path / "plain.yaml"
    plain.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      zeta1: 0.45\n")
    node2, *_ = harness("--params-file", str(plain))
    assert node2._unused == "" and node2._compensating == []


def test_a_drifting_sensor_is_said_in_the_params_file_and_a_bad_side_is_refused(harness, tmp_path):
    """``drift.side: sensor``: compensated by every law (open loop needs no reading for a drifting sensor, so it is
    not reported as uncompensated); a side the effect does not know is refused with the reason."""
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: [drift]\n"
                 "      zeta1: 0.45\n      y_scale: 5.0e-06\n      dt: 0.001\n"
                 "      drift:\n        side: sensor\n        c1: 1.0e-8\n")
    node, peer, ex, pub, got = harness("--params-file", str(p))
    assert node._compensating == ["drift"] and "open_loop does not compensate drift" not in node._unused
    assert dict(node._settings.effect_values)["drift.side"] == "sensor"
    res = node.set_parameters([Parameter("model.drift.side", value="amplifier")])[0]
    assert not res.successful and "drift.side must be one of stage, sensor" in res.reason
    assert node.get_parameter("model.drift.side").value == "sensor"


def test_an_effect_the_laws_cannot_invert_is_refused_with_a_reason(harness, tmp_path):
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: [creep]\n"
                 "      creep:\n        gain: 0.29\n        tilt: 0.0\n")
    with pytest.raises(Exception, match="creep"):
        harness("--params-file", str(p))


def test_a_second_command_publisher_is_reported(harness):
    """Two sources of /stage/command (a second controller, an excitation node): WARN on /diagnostics."""
    node, peer, ex, pub, got = harness()
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    pub.publish(_state(0, 10e-6, 50.0))

    def warned() -> bool:
        return any(s.level >= DiagnosticStatus.WARN and "other publisher" in s.message
                   for d in got["diag"] for s in d.status)

    # alone on the topic: diagnostics arrive, none of them names another publisher
    assert _spin_until(ex, lambda: len(got["diag"]) >= 2, 10.0)
    assert not warned()
    rival = peer.create_publisher(JointState, "/stage/command", 10)
    assert _spin_until(ex, warned, 15.0)
    vals = {kv.key: kv.value for s in got["diag"][-1].status for kv in s.values}
    assert vals["other_command_publishers"] == "1"
    peer.destroy_publisher(rival)


def test_a_pushed_model_with_effects_is_compensated_and_a_plain_push_clears_them(harness):
    """What hyst_ident_node pushes (controller_parameters) for mbw + creep is taken whole; then a plain MBW."""
    from hyst_model.core import pea_default
    from hyst_model.effects import compose
    from hyst_model.ident_node import controller_parameters
    from hyst_model.models import BASE_MODELS

    node, peer, ex, pub, got = harness("-p", "rate:=2000.0")
    cfg = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 5e-4}
    m = compose(BASE_MODELS["mbw"](cfg), ["creep"], cfg)
    theta = m.pack({**pea_default().to_dict(), "creep.gain": 0.012, "creep.tilt": 0.0})
    r = node.set_parameters_atomically(controller_parameters(m, theta, 5e-4))
    assert r.successful, r.reason
    assert node._compensating == ["creep"] and node._unused == ""
    plain = BASE_MODELS["mbw"](cfg)
    r = node.set_parameters_atomically(controller_parameters(plain, plain.pack(pea_default().to_dict()), 5e-4))
    assert r.successful, r.reason
    assert node._compensating == [] and node._settings.effects == ()


def test_a_model_that_diverges_within_the_command_limits_is_refused_where_it_runs_open_loop(harness, tmp_path):
    """An MBW that runs away on commands within v_min..v_max and the slew limit (hyst_model.core.bounded): the
    open-loop inverse and a delay's Smith predictor follow its prediction, so a push is rejected with the reason
    (and a params file refused at start); DPPC inverts it one step from the measurement, so it runs, with the
    divergence on /diagnostics as a WARN. The profile's own model passes the same probe."""
    from hyst_model.core import pea_default
    node, peer, ex, pub, got = harness("-p", "algorithm:=open_loop")
    assert node._settings.divergence == ""
    bad = pea_default().alpha1 * 0 + 1.0  # alpha1 = 1: finite on a sine, runs away on steps across the range
    res = node.set_parameters([Parameter("model.alpha1", value=bad)])[0]
    assert not res.successful and "diverges" in res.reason and "open-loop inverse" in res.reason
    assert node.get_parameter("model.alpha1").value != bad
    assert node.set_parameters([Parameter("algorithm", value="dppc")])[0].successful
    assert node.set_parameters([Parameter("model.alpha1", value=bad)])[0].successful
    assert "diverges" in node._settings.divergence and "dppc inverts it one step" in node._settings.divergence
    # back to the open-loop inverse on this model: refused
    res = node.set_parameters([Parameter("algorithm", value="open_loop")])[0]
    assert not res.successful and "diverges" in res.reason
    # with a delay (a Smith predictor on the base model) even DPPC refuses it
    res = node.set_parameters_atomically([Parameter("model.effects", value=["delay"]),
                                          Parameter("model.delay.tau", value=0.001)])
    assert not res.successful and "delay predictor" in res.reason
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    pub.publish(_state(0, 10e-6, 50.0))

    def warned() -> bool:
        return any(s.level >= DiagnosticStatus.WARN and "diverges" in s.message for d in got["diag"] for s in d.status)

    assert _spin_until(ex, warned, 5.0)
    p = tmp_path / "bad.yaml"
    p.write_text(f"/**:\n  ros__parameters:\n    algorithm: open_loop\n    model:\n      base: mbw\n"
                 f"      alpha1: {bad}\n")
    with pytest.raises(Exception, match="diverges"):
        harness("--params-file", str(p))


@pytest.mark.parametrize("in_process", [True, False])
def test_an_in_process_reference_is_sampled_exactly_at_each_state(harness, in_process):
    """``follow`` (hyst_loop_node's wiring): the target of the command answering state k is r(t_k + 1/rate), with
    no topic and no extrapolation — a stage that sits exactly on r has zero tracking error. Without it (no
    /stage/reference either) the controller holds where the stage is and the same stage shows an error."""
    node, peer, ex, pub, got = harness("-p", "watchdog_periods:=100000")

    def r(t: float) -> float:
        return 15e-6 + 5e-6 * math.sin(2 * math.pi * 5.0 * (t - 100.0))

    if in_process:
        node.follow(r)
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    n = 400  # the first 0.25 s after a start are left out of the statistics
    for k in range(n):
        pub.publish(_state(k, r(100 + k // 1000 + (k % 1000) * 1e-3), 50.0))
        assert _spin_until(ex, lambda: len(got["cmd"]) > k)
    st = node.tracking_summary()["dppc"]
    assert st["samples"] == n - 250
    if in_process:
        assert st["rmse"] < 1e-12
    else:
        assert st["rmse"] > 5e-8


def test_pid_defaults_keep_the_peas_loop_gain_on_the_start_up_model(harness):
    """The SI defaults are the PEA's; on the GMA profile (4 µm/V, 20× the PEA's) they are declared a 20th, and an
    explicit value is the user's."""
    from hyst_control.pid import PIDGains, gains_for
    from hyst_model.core import stage_model

    pea, *_ = harness()
    assert pea.get_parameter("pid.kp").value == PIDGains().kp and pea.get_parameter("pid.ki").value == PIDGains().ki
    gma, *_ = harness("-p", "profile:=gma")
    want = gains_for(stage_model("gma"), -5.0, 5.0)
    assert gma.get_parameter("pid.kp").value == pytest.approx(want.kp) and 0.03 < want.kp / PIDGains().kp < 0.07
    assert gma.get_parameter("pid.ki").value == pytest.approx(want.ki)
    mine, *_ = harness("-p", "profile:=gma", "-p", "pid.kp:=123456.0")
    assert mine.get_parameter("pid.kp").value == 123456.0



def test_a_custom_stage_runs_on_its_own_range_model_and_stroke(harness, ten_volt_stage):
    """profile custom: a ±10 V amplifier (beyond the ±200 V static range's GMA/PEA defaults) with the stage model of
    its params file; the limits, the watchdog's rest voltage and the internal reference are the stage's."""
    node, peer, ex, pub, got = harness("--params-file", ten_volt_stage, "-p", "profile:=custom",
                                       "-p", "v_min:=-10.0", "-p", "v_max:=10.0", "-p", "reference:=sine:5")
    s = node._settings
    assert (s.limits.v_min, s.limits.v_max, s.limits.v_safe, s.limits.slew_max) == (-10.0, 10.0, 0.0, 2e4)
    assert s.model.u_scale == 1.0
    lo, hi = s.model.rest_output(-10.0), s.model.rest_output(10.0)
    assert lo < s.reference.offset - s.reference.amplitude < s.reference.offset + s.reference.amplitude < hi
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    pub.publish(_state(0, 0.0, 0.0))
    assert _spin_until(ex, lambda: len(got["cmd"]) > 0)
    assert -10.0 <= got["cmd"][-1].effort[0] <= 10.0
    # a 1 kV amplifier's range is declared for custom; the PEA/GMA profiles keep their ±200 V
    assert node.describe_parameter("v_max").floating_point_range[0].to_value == 1000.0


@pytest.mark.parametrize(("cli", "why"), [
    (("-p", "profile:=custom", "-p", "v_min:=-10.0", "-p", "v_max:=10.0"), "needs the stage's model"),
    (("-p", "profile:=custom", "--params-file", "STAGE"), "needs v_min and v_max"),
    (("-p", "profile:=pae",), "unknown profile 'pae'"),
])
def test_a_custom_stage_without_its_model_or_range_and_an_unknown_profile_are_refused(harness, ten_volt_stage, cli,
                                                                                       why):
    """An unknown profile name ran the PEA's limits without a word; custom without its range or model is refused."""
    cli = tuple(ten_volt_stage if a == "STAGE" else a for a in cli)
    with pytest.raises(Exception, match=why):
        harness(*cli)


def test_a_corrupt_state_is_held_like_a_nan_and_reported(harness):
    """A finite but impossible sample (1e300 m, 1 m on a 30 µm stage, 1e300 V applied) stepped the command by
    75 V; it is held as a NaN is, counted, and /diagnostics turns WARN while it happens."""
    node, peer, ex, pub, got = harness("-p", "reference:=constant:15", "-p", "watchdog_periods:=100000")
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    k = 0
    for _ in range(10):
        pub.publish(_state(k, 14e-6, 70.0))
        k += 1
        assert _spin_until(ex, lambda: len(got["cmd"]) >= k)
    for y, u in ((1e300, 70.0), (1.0, 70.0), (-1.0, 70.0), (14e-6, 1e300)):
        held = node._ctrl.last_command
        pub.publish(_state(k, y, u))
        k += 1
        assert _spin_until(ex, lambda: len(got["cmd"]) >= k)
        assert got["cmd"][-1].effort[0] == held, (y, u)
    assert node.counts["bad_states"] == 4
    assert _spin_until(ex, lambda: any(s.level == DiagnosticStatus.WARN and "corrupt" in s.message
                                       for d in got["diag"] for s in d.status), timeout=5.0)
    # a plausible sample is used again (a stage a little beyond its rest travel is no corrupt sample)
    pub.publish(_state(k, 31e-6, 150.0))
    assert _spin_until(ex, lambda: len(got["cmd"]) > k) and node.counts["bad_states"] == 4


def test_the_watchdog_ramps_to_v_safe_instead_of_jumping(harness):
    node, peer, ex, pub, got = harness("-p", "rate:=1000.0", "-p", "watchdog_periods:=20", "-p", "v_safe:=0.0",
                                       "-p", "safe_ramp_rate:=200.0", "-p", "reference:=constant:15")
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    for k in range(5):
        pub.publish(_state(k, 15e-6, 75.0))
        _spin_until(ex, lambda: len(got["cmd"]) > k)
    n0 = len(got["cmd"])
    start = got["cmd"][-1].effort[0]
    assert start > 20.0
    assert _spin_until(ex, lambda: got["cmd"][-1].effort[0] <= 1e-9, timeout=20.0)
    u = [m.effort[0] for m in got["cmd"][n0 - 1:]]
    steps = [a - b for a, b in zip(u, u[1:])]
    assert min(steps) >= -1e-9 and max(steps) <= 200.0 * 0.1 + 1e-9  # down only, never more than 0.1 s of ramp
    assert len(u) > 5  # a ramp, not a jump


def test_a_reference_beyond_the_travel_is_reported_and_a_profile_range_is_kept(harness):
    # 31 µm: beyond the 30 µm travel, within the tenth of it a generated reference may leave it by
    node, peer, ex, pub, got = harness("-p", "reference:=constant:31", "-p", "watchdog_periods:=100000")
    assert _spin_until(ex, lambda: pub.get_subscription_count() > 0)
    for k in range(3):
        pub.publish(_state(k, 15e-6, 75.0))
        assert _spin_until(ex, lambda: len(got["cmd"]) > k)
    assert node.counts["unreachable_refs"] == 3
    assert _spin_until(ex, lambda: any(s.level == DiagnosticStatus.WARN and "beyond the stage's travel" in s.message
                                       for d in got["diag"] for s in d.status), timeout=5.0)
    res = node.set_parameters([Parameter("v_max", value=200.0)])[0]  # the PEA amplifier stops at 150 V
    assert not res.successful and "profile pea" in res.reason


def test_every_parameter_can_be_read_back_as_a_dump_does(harness, tmp_path):
    """model.effects was declared typed but without a value (and ``effects: []`` in a params file left it unset):
    a get of all parameters — what a parameter dump does — then answered nothing."""
    node, *_ = harness()
    names = list(node._parameters)
    assert len(node.get_parameters(names)) == len(names) and node.get_parameter("model.effects").value == [""]
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: []\n      zeta1: 0.45\n")
    node, *_ = harness("--params-file", str(p))
    assert node.get_parameter("model.effects").value == [""] and node._settings.effects == ()
    assert len(node.get_parameters(list(node._parameters))) == len(node._parameters)


def test_a_reference_far_beyond_the_travel_is_refused_as_a_parameter_and_ignored_as_a_message(harness):
    """``sine:5:1e300`` was taken and swung the commands between the range's ends; a 1e300 m reference message
    likewise: now the parameter is refused with the span, and the message counted as corrupt and not followed."""
    node, peer, ex, pub, got = harness("-p", "watchdog_periods:=100000")
    res = node.set_parameters([Parameter("reference", value="sine:5:1e300")])[0]
    assert not res.successful and "beyond the model's travel" in res.reason
    assert node.set_parameters([Parameter("reference", value="sine:5:12")])[0].successful  # 3..27 µm
    assert node.set_parameters([Parameter("reference", value="")])[0].successful  # follow the topic
    ref_pub = peer.create_publisher(JointState, "/stage/reference", 10)
    assert _spin_until(ex, lambda: ref_pub.get_subscription_count() > 0)
    m = JointState()
    m.position = [1e300]
    ref_pub.publish(m)
    assert _spin_until(ex, lambda: node.counts["bad_refs"] == 1)
    assert node._ref is None  # not followed
    # a sane position with a corrupt velocity (µm/s sent as m/s, or 1e300): the position is followed, the velocity
    # is not extrapolated (it drove every command to 150 V) and the sample is counted
    for k, v in enumerate((62.8, 1e300, -float("inf"))):
        m = JointState()
        m.position, m.velocity = [15e-6], [v]
        ref_pub.publish(m)
        assert _spin_until(ex, lambda k=k: node.counts["bad_refs"] == 2 + k)
        assert node._ref is not None and node._ref[1] == 15e-6 and node._ref[2] == 0.0
    m = JointState()
    m.position, m.velocity = [15e-6], [1e-3]  # 1 mm/s: a stage can follow that
    ref_pub.publish(m)
    assert _spin_until(ex, lambda: node._ref is not None and node._ref[2] == 1e-3)
    assert node.counts["bad_refs"] == 4
