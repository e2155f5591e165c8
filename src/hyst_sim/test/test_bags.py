"""Raw bag IO, the recorder and the player: tiny bags in tmp_path, record → play round trip keeping timing."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from hyst_common.node import KEEP_ALL_RELIABLE
from hyst_sim.bagio import RawBagWriter, bag_topics, read_raw
from hyst_sim.errors import BagError
from hyst_sim.play_node import PlayNode
from hyst_sim.record_node import RecordNode

pytestmark = pytest.mark.ros

T0 = 1_700_000_000_000_000_000
# irregular gaps (s) so that "keeps the timing" cannot pass by accident
TIMES = [0.0, 0.05, 0.06, 0.20, 0.45, 0.46, 0.70]


def _ts():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def _state(k: int) -> bytes:
    """Exact CDR as a subscription receives it (rclpy's serialize_message appends padding bytes)."""
    ts = _ts()
    T, H, JS = (ts.types[n] for n in ("builtin_interfaces/msg/Time", "std_msgs/msg/Header",
                                      "sensor_msgs/msg/JointState"))
    m = JS(H(T(100 + k, 1000 * k), ""), ["stage"], np.array([k * 1e-6]), np.array([], float), np.array([float(k)]))
    return bytes(ts.serialize_cdr(m, "sensor_msgs/msg/JointState"))


def _float(k: int) -> bytes:
    ts = _ts()
    return bytes(ts.serialize_cdr(ts.types["std_msgs/msg/Float64"](float(k)), "std_msgs/msg/Float64"))


def _synthetic_bag(path: Path) -> list:
    msgs = []
    with RawBagWriter(path) as w:
        w.add_topic("/stage/state", "sensor_msgs/msg/JointState")
        w.add_topic("/test/scalar", "std_msgs/msg/Float64")
        for k, t in enumerate(TIMES):
            topic = "/stage/state" if k % 3 else "/test/scalar"
            data = _state(k) if k % 3 else _float(k)
            w.write(topic, T0 + int(t * 1e9), data)
            msgs.append((topic, int(t * 1e9), data))
    return msgs


def test_raw_bag_round_trip_and_refusals(tmp_path):
    bag = tmp_path / "b"
    msgs = _synthetic_bag(bag)
    assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap"))
    assert "zstd" in (bag / "metadata.yaml").read_text() or b"zstd" in next(bag.glob("*.mcap")).read_bytes()
    got = list(read_raw(bag))
    assert [(m.topic, m.t_ns - T0, m.data) for m in got] == msgs
    assert bag_topics(bag) == {"/stage/state": "sensor_msgs/msg/JointState", "/test/scalar": "std_msgs/msg/Float64"}
    assert [m.topic for m in read_raw(bag, ["/test/scalar"])] == ["/test/scalar"] * 3
    with pytest.raises(BagError, match="no topic"):
        list(read_raw(bag, ["/nope"]))
    with pytest.raises(BagError, match="exists"):
        RawBagWriter(bag)
    with pytest.raises(BagError, match="no such"):
        list(read_raw(tmp_path / "missing"))
    with RawBagWriter(tmp_path / "c") as w, pytest.raises(BagError, match="not a standard"):
        w.add_topic("/x", "my_pkg/msg/Custom")
    from hyst_model.io.bag import read_state_bag                      # the analysis reader reads our bags
    rec = read_state_bag(bag)
    np.testing.assert_allclose(rec.y, [k * 1e-6 for k in range(len(TIMES)) if k % 3])


def test_record_then_play_round_trip_keeps_timing(tmp_path):
    src = tmp_path / "src"
    msgs = _synthetic_bag(src)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    writer = RawBagWriter(tmp_path / "out")
    rec = play = None
    try:
        # /stage/state has a contract type (subscribed at once); /test/scalar is found through the ROS graph
        rec = RecordNode(writer, ["/stage/state", "/test/scalar"], context=ctx)
        play = PlayNode(list(read_raw(src)), rate=1.0, wait_for_subscribers=10.0, delay=0.3, context=ctx)
        ex.add_node(rec)
        ex.add_node(play)
        end = time.monotonic() + 5.0                       # let the recorder discover both topics first
        while len(rec._subs) < 2 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        play.start()
        end = time.monotonic() + 60.0                      # until the recorder has taken every message
        while (not play.done.is_set() or rec.received < len(msgs)) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        rec.flush()
    finally:
        writer.close()
        ex.shutdown()
        for node in (play, rec):
            if node is not None:
                if node is play:
                    play.stop()
                node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    got = list(read_raw(tmp_path / "out"))
    assert play.published == len(msgs)
    assert sorted((m.topic, m.data) for m in got) == sorted((t, d) for t, _, d in msgs)
    # the player's schedule is the recording's (the 10 ms and 250 ms gaps), and it never publishes early: a
    # loaded machine can only delay a message, which the recorder then stamps as received
    t_orig = np.array([t for _, t, _ in msgs], dtype=float) * 1e-9
    assert [i for i, _, _ in play.sent] == list(range(len(msgs)))
    np.testing.assert_allclose([d for _, d, _ in play.sent], t_orig - t_orig[0], atol=1e-9)
    assert all(at >= due for _, due, at in play.sent), play.sent
    js = deserialize_message(got[[m.topic for m in got].index("/stage/state")].data, JointState)
    assert js.name == ["stage"]


def test_player_rate_factor_and_loop(tmp_path):
    src = tmp_path / "src"
    _synthetic_bag(src)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        fast = PlayNode(list(read_raw(src)), rate=4.0, context=ctx)
        fast.start()
        assert fast.done.wait(60.0)
        assert fast.published == len(TIMES)
        # four times faster: due at a quarter of the recorded offsets, and never published before that
        np.testing.assert_allclose([d for _, d, _ in fast.sent], np.array(TIMES) / 4.0, atol=1e-9)
        assert all(at >= due for _, due, at in fast.sent)
        looping = PlayNode(list(read_raw(src)), rate=10.0, loop=True, context=ctx)
        looping.start()
        end = time.monotonic() + 60.0
        while looping.published <= 2 * len(TIMES) and time.monotonic() < end:
            time.sleep(0.01)
        looping.stop()
        assert looping.published > 2 * len(TIMES)
        idx = [i for i, _, _ in looping.sent]
        assert idx[:2 * len(TIMES)] == 2 * list(range(len(TIMES)))    # starts over after the last message
        with pytest.raises(BagError):
            PlayNode([], context=ctx)
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_recorder_process_finalises_the_bag_on_signal(tmp_path, sig):
    exe = Path(sys.executable).with_name("hyst_bag_record")
    out = tmp_path / "rec"
    proc = subprocess.Popen([str(exe), "/stage/state", "-o", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("pub", context=ctx)
    pub = node.create_publisher(JointState, "/stage/state", KEEP_ALL_RELIABLE)
    try:
        end = time.monotonic() + 60.0
        k = 0
        while time.monotonic() < end and (k < 50 or pub.get_subscription_count() == 0):
            if pub.get_subscription_count():
                m = JointState()
                m.name, m.position, m.effort = ["stage"], [k * 1e-9], [0.0]
                pub.publish(m)
                k += 1
            time.sleep(0.01)
        assert pub.wait_for_all_acked(Duration(seconds=60))  # all in the recorder's reader: a condition, not a time
        proc.send_signal(sig)
        out_text, err_text = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, err_text.decode()
    assert b"messages" in out_text
    got = list(read_raw(out))
    assert len(got) == k  # the drain after the signal takes what was delivered
    assert (out / "metadata.yaml").is_file()
    existing = subprocess.run([str(exe), "/stage/state", "-o", str(out)], capture_output=True, timeout=30)
    assert existing.returncode == 2 and b"exists" in existing.stderr and b"Traceback" not in existing.stderr


@pytest.mark.slow
def test_recorder_keeps_every_sample_and_survives_repeated_signals(tmp_path):
    """Issue 11: samples lost mid-run, and a second Ctrl-C during finalisation left an unreadable bag."""
    exe = Path(sys.executable).with_name("hyst_bag_record")
    out = tmp_path / "rec"
    proc = subprocess.Popen([str(exe), "/stage/state", "-o", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("pub", context=ctx)
    # keep-all, as the lockstep sim's: the guarantee is every sample of a publisher that waits for its reliable
    # readers (the realtime sim's keep-last 1000 loses samples to a reader more than 0.5 s behind at 2 kHz, by
    # design, which a loaded test machine can be)
    pub = node.create_publisher(JointState, "/stage/state", KEEP_ALL_RELIABLE)
    n = 4000
    try:
        end = time.monotonic() + 30.0
        while pub.get_subscription_count() == 0 and time.monotonic() < end:
            time.sleep(0.01)
        assert pub.get_subscription_count() == 1
        t0 = time.monotonic()
        for k in range(n):  # ~2 kHz, paced, compressed output
            m = JointState()
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(k * 500_000, 1_000_000_000)
            m.name, m.position, m.effort = ["stage"], [k * 1e-9], [0.0]
            pub.publish(m)
            wait = t0 + (k + 1) * 5e-4 - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        # every sample in the recorder's reader before the stop (a condition, not a time: on a loaded machine
        # the recorder may still be taking them; the drain after the signal takes the rest)
        assert pub.wait_for_all_acked(Duration(seconds=60))
        proc.send_signal(signal.SIGINT)
        lines = []
        for line in proc.stderr:  # wait until it finalises (the drain is over), then be impatient
            lines.append(line)
            if b"finalising the bag" in line:
                break
        for _ in range(20):
            if proc.poll() is not None:
                break
            proc.send_signal(signal.SIGINT)
            time.sleep(0.02)
        out_text, err_rest = proc.communicate(timeout=60)
        err_text = b"".join(lines) + err_rest
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, err_text.decode()
    got = list(read_raw(out))
    assert len(got) == n


@pytest.mark.parametrize("topic", ["bad-topic:sensor_msgs/msg/JointState", "bad-topic", "/stage/1state"])
def test_recorder_refuses_a_topic_name_ros_cannot_use_before_it_starts(tmp_path, topic):
    """With a type it was a traceback (exit 1); without one it recorded nothing and exited 0."""
    exe = Path(sys.executable).with_name("hyst_bag_record")
    proc = subprocess.run([str(exe), topic, "-o", str(tmp_path / "bag"), "--duration", "1"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and "not a valid ROS topic name" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "bag").exists()


def test_recorder_refuses_a_message_type_it_cannot_record_and_a_bag_folder_that_is_a_file(tmp_path):
    """A mistyped type recorded nothing into an empty bag and exited 0; ./bags being a file was a traceback."""
    exe = Path(sys.executable).with_name("hyst_bag_record")
    proc = subprocess.run([str(exe), "/stage/state:sensor_msgs/msg/JointStates", "-o", str(tmp_path / "bag"),
                           "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "JointStates" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "bag").exists()
    (tmp_path / "bags").write_text("mine")
    proc = subprocess.run([str(exe), "--duration", "0.2"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and "cannot create the bag folder" in proc.stderr and "Traceback" not in proc.stderr
    assert (tmp_path / "bags").read_text() == "mine"


@pytest.mark.parametrize("argv", [["--delay", "inf"], ["--delay", "1e10"], ["--wait-for-subscribers", "nan"],
                                  ["--rate", "inf"]])
def test_player_refuses_waits_it_cannot_keep(tmp_path, argv):
    """--delay inf killed the player thread (time_t overflow) and it published nothing, exit 0."""
    exe = Path(sys.executable).with_name("hyst_bag_play")
    proc = subprocess.run([str(exe), str(tmp_path / "nobag"), *argv], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and argv[0] in proc.stderr and "Traceback" not in proc.stderr
