"""rosbag2 IO through rosbags: round trips in every storage form, and one clear DataError for every bad bag."""
import numpy as np
import pytest

from hyst_model.errors import DataError
from hyst_model.io import list_topics, load_record, read_joint_states, read_state_bag, write_state_bag


def _data(n=200):
    t = np.arange(n) * 5e-4
    u = 75 + 75 * np.sin(2 * np.pi * 5 * t)
    return t, u, 1e-7 * u - 1.6e-6


@pytest.mark.parametrize("form", ["mcap_dir", "mcap_file", "sqlite3"])
def test_round_trip(tmp_path, form):
    t, u, y = _data()
    path = {"mcap_dir": tmp_path / "bag", "mcap_file": tmp_path / "run.mcap", "sqlite3": tmp_path / "bag3"}[form]
    write_state_bag(path, t, u, y, t0_ns=1_700_000_000_123_456_789, storage="sqlite3" if form == "sqlite3" else "mcap")
    rec = read_state_bag(path)
    np.testing.assert_allclose(rec.t, t, atol=1e-9)  # stamps are integer ns
    np.testing.assert_array_equal(rec.u, u)
    np.testing.assert_array_equal(rec.y, y)
    assert rec.meta["t0_ns"] == 1_700_000_000_123_456_789 and rec.meta["time_source"] == "header.stamp"
    rec.check()


def test_mcap_is_chunk_compressed(tmp_path):
    t, u, y = _data(2000)
    write_state_bag(tmp_path / "z", t, u, y)
    write_state_bag(tmp_path / "raw", t, u, y, compress=False)
    def size(p):
        return sum(f.stat().st_size for f in p.glob("*.mcap"))
    assert size(tmp_path / "z") < 0.7 * size(tmp_path / "raw")


def test_extra_topics_and_named_columns(tmp_path):
    t, u, y = _data(50)
    extra = {"/controller/state": {"t": t[:10], "name": ["error", "nu"],
                                   "position": np.c_[np.arange(10), -np.arange(10)]}}
    write_state_bag(tmp_path / "b", t, u, y, extra=extra)
    topics = list_topics(tmp_path / "b")
    assert topics == {"/stage/state": ("sensor_msgs/msg/JointState", 50),
                      "/controller/state": ("sensor_msgs/msg/JointState", 10)}
    js = read_joint_states(tmp_path / "b", "/controller/state")
    np.testing.assert_array_equal(js.column("nu"), -np.arange(10))
    np.testing.assert_array_equal(js.column("missing"), np.full(10, np.nan))


def test_custom_topic_and_out_of_order_messages_are_sorted(tmp_path):
    t, u, y = _data(30)
    order = np.r_[0:10, 20:30, 10:20]  # recorder wrote in a different order than sampled
    write_state_bag(tmp_path / "b", t[order], u[order], y[order], topic="/pea/state")
    rec = read_state_bag(tmp_path / "b", "/pea/state")
    np.testing.assert_array_equal(rec.u, u)


def test_missing_topic_names_the_available_ones(tmp_path):
    t, u, y = _data()
    write_state_bag(tmp_path / "b", t, u, y)
    with pytest.raises(DataError, match=r"no topic '/nope'.*/stage/state"):
        read_state_bag(tmp_path / "b", "/nope")


def test_empty_bag(tmp_path):
    write_state_bag(tmp_path / "e", [], [], [])
    with pytest.raises(DataError, match="no messages"):
        read_state_bag(tmp_path / "e")


@pytest.mark.parametrize("single", [False, True])
def test_truncated_bag(tmp_path, single):
    t, u, y = _data(3000)
    path = tmp_path / ("b.mcap" if single else "b")
    write_state_bag(path, t, u, y)
    f = path if single else next(path.glob("*.mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])  # a recorder killed mid-write
    with pytest.raises(DataError, match="b"):
        read_state_bag(path)


def test_not_a_bag(tmp_path):
    with pytest.raises(DataError, match="no such"):
        read_state_bag(tmp_path / "nothing")
    (tmp_path / "d").mkdir()
    with pytest.raises(DataError, match="not a bag .a rosbag2 directory holds metadata.yaml"):
        read_state_bag(tmp_path / "d")


def test_nan_rows_and_gaps_are_reported_by_check(tmp_path):
    t, u, y = _data(100)
    y[40] = np.nan
    write_state_bag(tmp_path / "nan", t, u, y)
    with pytest.raises(DataError, match=r"1 row\(s\) with NaN"):
        load_record(tmp_path / "nan").check()
    t2, u2, y2 = _data(100)
    keep = np.r_[0:50, 60:100]  # ten samples lost
    write_state_bag(tmp_path / "gap", t2[keep], u2[keep], y2[keep])
    rec = load_record(tmp_path / "gap")
    with pytest.raises(DataError, match="gap"):
        rec.check()
    assert len(rec.longest_segment().check()) == 50


def test_never_overwrites_a_bag(tmp_path):
    t, u, y = _data(10)
    write_state_bag(tmp_path / "b", t, u, y)
    with pytest.raises(DataError, match="exists"):
        write_state_bag(tmp_path / "b", t, u, y)


def test_columns_option_rejected_for_bags(tmp_path):
    t, u, y = _data(10)
    write_state_bag(tmp_path / "b", t, u, y)
    with pytest.raises(DataError, match="CSV"):
        load_record(tmp_path / "b", columns="a,b,c")


@pytest.mark.parametrize("single", [False, True])
def test_salvage_reads_a_killed_recorders_bag_up_to_the_damage(tmp_path, single):
    t, u, y = _data(3000)
    path = tmp_path / ("b.mcap" if single else "b")
    write_state_bag(path, t, u, y)
    f = path if single else next(path.glob("*.mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.8)])  # footer, summary and indexes gone; the chunks are intact
    with pytest.raises(DataError):
        read_state_bag(path)
    rec = read_state_bag(path, salvage=True)
    assert rec.meta["salvaged"] and len(rec) == 3000
    np.testing.assert_array_equal(rec.u, u[: len(rec)])
    rec.check()
    with pytest.raises(DataError, match="nothing on '/other'"):
        read_state_bag(path, "/other", salvage=True)
    f.write_bytes(data[:2000])  # cut inside the only chunk: nothing to salvage, still one clear error
    with pytest.raises(DataError, match="could be salvaged"):
        read_state_bag(path, salvage=True)
