"""hyst_excite_node against the realtime sim (in one isolated context) and its start-up refusals."""
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from hyst_control.excite_node import ExciteNode
from hyst_sim.sim_node import SimNode

pytestmark = pytest.mark.ros


def test_plays_the_excitation_on_a_realtime_stage_time_indexed_and_stops(ctx):
    rate = 500.0
    sim = SimNode(context=ctx, parameter_overrides=[Parameter("rate", value=rate),
                                                     Parameter("command_timeout", value=5.0)])
    exc = ExciteNode(context=ctx, parameter_overrides=[
        Parameter("rate", value=rate), Parameter("parts", value="steps,triangles"), Parameter("n_steps", value=3),
        Parameter("hold", value=0.1), Parameter("periods", value=1), Parameter("amplitudes", value=[0.5, 1.0])])
    tester = rclpy.create_node("tester", context=ctx)
    states, cmds = [], []
    tester.create_subscription(JointState, "/stage/state", states.append, 1000)
    tester.create_subscription(JointState, "/stage/command", cmds.append, 1000)
    ex = SingleThreadedExecutor(context=ctx)
    for n in (sim, exc, tester):
        ex.add_node(n)
    try:
        end = time.monotonic() + 120
        while not exc.done and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        assert exc.done, "the excitation did not finish"
        u = exc.excitation.u
        assert np.all(u >= 0.0) and np.all(u <= 150.0)
        assert exc.answered >= 0.5 * len(u)  # realtime: some states may be missed under load
        # every command answers a state with its stamp and is the time-indexed excitation sample, except within
        # step_rise after a gap (missed periods under load), where it fades from the held voltage towards it
        t0 = exc._t_first
        # (the fade keeps the offset the gap left, held voltage − excitation, and shrinks it; the excitation itself
        # may move meanwhile, so the command is judged against the offset, not against the previous command)
        t_gap, prev, off = -1.0, None, 0.0
        for c in cmds[:-1]:
            t = c.header.stamp.sec + 1e-9 * c.header.stamp.nanosec
            k = int(round((t - t0) * rate)) + 1
            if prev is not None and k > prev[0] + 1:
                t_gap, off = t, prev[1] - u[k]
            if t - t_gap >= exc.spec.step_rise:
                assert c.effort[0] == u[k]
            else:
                d = c.effort[0] - u[k]
                assert abs(d) <= abs(off) + 1e-9 and d * off >= -1e-12, (d, off)
            prev = (k, c.effort[0])
        assert cmds[-1].effort[0] == exc.spec.rest
    finally:
        ex.shutdown()
        for n in (sim, exc, tester):
            n.destroy_node()


def test_a_gap_is_faded_in_not_jumped(ctx):
    """After missed periods the stage held the old voltage; the excitation resumes over step_rise, on time."""
    rate = 1000.0
    exc = ExciteNode(context=ctx, parameter_overrides=[Parameter("rate", value=rate), Parameter("parts", value="steps"),
                                                        Parameter("n_steps", value=6), Parameter("hold", value=0.2)])
    sent = []
    exc._pub.publish = sent.append  # capture the answers; no graph needed
    exc._pub.get_subscription_count = lambda: 1
    u, rise = exc.excitation.u, exc.spec.step_rise

    def answer(k):  # the state stamped k periods after the first
        m = JointState()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(k * 1_000_000, 1_000_000_000)
        m.position = [1e-6]
        exc._on_state(m)
        return sent[-1].effort[0]

    try:
        jumps = np.abs(u[300:] - u[:-300])
        k0 = int(np.argmax(jumps[:len(u) - 400]))     # a gap of 300 periods across a large change
        assert jumps[k0] > 40.0
        for k in range(k0 - 1):
            assert answer(k) == u[k + 1]               # time-indexed, before any gap
        held = answer(k0 - 1)
        n = int(round(rise * rate))
        after = [answer(k) for k in range(k0 + 299, k0 + 299 + n + 3)]
        expect = u[k0 + 300:k0 + 300 + n + 3]
        assert abs(after[0] - held) < 1e-9                          # resumes from the held voltage ...
        assert np.all(np.abs(np.diff(after)) <= np.pi / 2 * jumps[k0] / n + np.abs(np.diff(expect)) + 1e-9)
        np.testing.assert_array_equal(after[n:], expect[n:])       # ... and is on the excitation after step_rise
        assert answer(k0 + 299 + n + 3) == u[k0 + 300 + n + 3]     # the timing of the rest is unchanged
    finally:
        exc.destroy_node()


def test_a_stray_or_unreadable_state_is_counted_not_answered_and_a_real_pause_is_played_on(ctx):
    """One state stamped in 2033 with a NaN position ended a 17 800-sample excitation after 100 samples, silently."""
    from diagnostic_msgs.msg import DiagnosticArray

    exc = ExciteNode(context=ctx, parameter_overrides=[Parameter("rate", value=1000.0),
                                                        Parameter("parts", value="steps"),
                                                        Parameter("n_steps", value=30)])
    sent, diags = [], []
    exc._pub.publish = sent.append
    exc._pub.get_subscription_count = lambda: 1
    exc._diag_pub.publish = diags.append

    def state(sec, nsec=0, pos=(1e-6,)):
        m = JointState()
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
        m.position = list(pos)
        n = len(sent)
        exc._on_state(m)
        return len(sent) > n

    try:
        assert all(state(0, k * 1_000_000) for k in range(100))
        assert not state(2_000_000_000, pos=(float("nan"),))       # unreadable
        assert not state(2_000_000_000)                           # a jump of decades, unconfirmed
        assert not state(0, 50_000_000)                           # before the last state answered
        assert not state(0, 99_000_000, pos=())                   # no position at all
        assert state(0, 100_000_000) and not exc.done             # the run goes on where it was
        assert exc.ignored == {"unreadable": 2, "out_of_order": 1, "jump": 1}
        assert not state(3) and state(3, 1_000_000)               # a real 2.9 s pause: confirmed, played on
        k = 1 + int(round(1000 * (exc.spec.step_rise + 0.01)))  # past the fade from the held voltage
        assert all(state(3, 1_000_000 * j) for j in range(2, k + 1))
        assert sent[-1].effort[0] == exc.excitation.u[3000 + k + 1]  # on time
        exc._publish_diagnostics()
        st = diags[-1].status[0]
        vals = {kv.key: kv.value for kv in st.values}
        assert st.level == st.WARN and vals["ignored_jump"] == "2" and vals["ignored_unreadable"] == "2"
        assert isinstance(diags[-1], DiagnosticArray)
    finally:
        exc.destroy_node()


@pytest.mark.parametrize("bad", ["parts:=steps,chirp", "v_max:=200.0", "f_hi:=900.0", "profile:=xyz",
                                 "amplitudes:=[1.5]", "profile:=custom"])
def test_bad_start_parameter_is_one_line_and_exit_2(bad):
    exe = str(Path(sys.executable).parent / "hyst_excite_node")
    p = subprocess.run([exe, "--ros-args", "-p", bad], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ))
    assert p.returncode == 2, (bad, p.stderr)
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr, p.stderr


def test_plays_a_file_written_by_hyst_excite_sample_for_sample(ctx, tmp_path):
    """``hyst excite --out`` → ``-p file:=`` plays exactly those samples, time-indexed, then rests."""
    from hyst_model.cli.main import main as hyst
    f = tmp_path / "u.csv"
    assert hyst(["excite", "--out", str(f), "--rate", "1000", "--parts", "steps,noise", "--seconds", "0.5",
                 "--n-steps", "3", "--hold", "0.05", "--seed", "4"]) == 0
    t_file, u_file = np.loadtxt(f, delimiter=",", skiprows=1, unpack=True)
    exc = ExciteNode(context=ctx, parameter_overrides=[Parameter("rate", value=1000.0),
                                                        Parameter("file", value=str(f))])
    sent = []
    exc._pub.publish = sent.append  # capture the answers; no graph needed
    exc._pub.get_subscription_count = lambda: 1
    try:
        np.testing.assert_array_equal(exc.excitation.u, u_file)
        for k in range(len(u_file)):
            m = JointState()
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(k * 1_000_000, 1_000_000_000)
            m.position = [1e-6]
            exc._on_state(m)
        assert exc.done
        np.testing.assert_array_equal([c.effort[0] for c in sent[:-1]], u_file[1:])
        assert sent[-1].effort[0] == exc.spec.rest
    finally:
        exc.destroy_node()


def test_a_custom_range_file_plays_when_the_node_is_given_that_range(ctx, tmp_path):
    """A ±10 V stage's excitation (``hyst excite --profile custom``) plays with the range it printed."""
    from hyst_model.cli.main import main as hyst
    f = tmp_path / "u.csv"
    assert hyst(["excite", "--out", str(f), "--rate", "1000", "--profile", "custom", "--v-min", "-10",
                 "--v-max", "10", "--parts", "steps", "--n-steps", "3", "--hold", "0.05"]) == 0
    u_file = np.loadtxt(f, delimiter=",", skiprows=1, unpack=True)[1]
    assert u_file.min() < -5.0 or u_file.max() > 5.0          # beyond the GMA's ±5 V
    over = [Parameter("rate", value=1000.0), Parameter("file", value=str(f))]
    exc = ExciteNode(context=ctx, parameter_overrides=over + [
        Parameter("profile", value="custom"), Parameter("v_min", value=-10.0), Parameter("v_max", value=10.0)])
    try:
        np.testing.assert_array_equal(exc.excitation.u, u_file)
        assert exc.spec.rest == 0.0
    finally:
        exc.destroy_node()
    with pytest.raises(Exception, match="outside -5..5 V"):   # the GMA profile refuses the same file
        ExciteNode(context=ctx, parameter_overrides=over + [Parameter("profile", value="gma")])


def _file(tmp_path, rows):
    f = tmp_path / "bad.csv"
    f.write_text("t,u\n" + "".join(f"{a},{b}\n" for a, b in rows))
    return f


@pytest.mark.parametrize("rows,why", [
    ([(k * 1e-3, 0.0 if k in (0, 9) else 200.0) for k in range(10)], "outside 0..150 V"),
    ([(k * 2e-3, 0.0) for k in range(10)], "sampled every 0.001 s"),
    ([(k * 1e-3, 50.0) for k in range(10)], "starts at 50 V"),
    ([(0.0, 0.0), (0.0, 0.0), (0.001, 0.0)], "not strictly increasing"),
])
def test_a_file_breaking_a_limit_is_refused_at_start_in_one_line(tmp_path, rows, why):
    f = _file(tmp_path, rows)
    exe = str(Path(sys.executable).parent / "hyst_excite_node")
    p = subprocess.run([exe, "--ros-args", "-p", "rate:=1000.0", "-p", f"file:={f}"], capture_output=True,
                       text=True, timeout=120, env=dict(os.environ))
    assert p.returncode == 2, p.stderr
    line = p.stderr.strip()
    assert len(line.splitlines()) == 1 and "Traceback" not in line and why in line and str(f) in line, line
