"""rosbag2 input/output with ``rosbags`` (no rosbag2_py): the ``/stage/state`` contract of docs/ARCHITECTURE.md.

Reading accepts a rosbag2 directory (MCAP or sqlite3 storage) or a single ``.mcap`` file. The stage state is a
``sensor_msgs/msg/JointState`` stream: ``header.stamp`` is the sample time, ``position[0]`` the displacement (m),
``effort[0]`` the voltage actually applied (V). :func:`read_state_bag` returns a :class:`~hyst_model.io.record.Record`
with ``t`` relative to the first sample (the absolute first stamp is kept in ``meta['t0_ns']``).

Writing (:func:`write_state_bag`) produces a small rosbag2 with MCAP storage and zstd chunk compression — what the
tests of every package use to make bags in ``tmp_path`` — or a single ``.mcap`` file when the path ends in ``.mcap``.

Every failure a user can cause (missing path or topic, empty or truncated bag, wrong message type) becomes one
:class:`~hyst_model.errors.DataError` naming the bag.
"""
from __future__ import annotations

import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError
from .record import Record

__all__ = ["JointStates", "STATE_TOPIC", "list_topics", "read_joint_states", "read_state_bag", "salvage_joint_states",
           "write_state_bag"]

#: Default topic of the stage state stream (contract).
STATE_TOPIC = "/stage/state"
_JS = "sensor_msgs/msg/JointState"


def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


@dataclass
class JointStates:
    """All JointState messages of one topic, as arrays.

    Attributes
    ----------
    stamp_ns : ndarray of int64
        ``header.stamp`` per message (ns), in bag order.
    log_ns : ndarray of int64
        Bag receive/log time per message (ns).
    names : list of list of str
        ``name`` per message.
    position, velocity, effort : ndarray, shape (n, k)
        Values per message, NaN-padded to the widest message (k = max joint count, 0 if all empty).
    """

    stamp_ns: np.ndarray
    log_ns: np.ndarray
    names: list = field(default_factory=list)
    position: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    velocity: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    effort: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))

    def column(self, name: str, what: str = "position") -> np.ndarray:
        """Values of the joint called ``name`` (NaN where a message lacks it), e.g. ``column('error')``."""
        arr = getattr(self, what)
        out = np.full(len(self.names), np.nan)
        for i, ns in enumerate(self.names):
            if name in ns:
                j = ns.index(name)
                if j < arr.shape[1]:
                    out[i] = arr[i, j]
        return out


def _open_reader(path: Path):
    from rosbags.highlevel import AnyReader
    if not path.exists():
        raise DataError(f"{path}: no such bag (expected a rosbag2 directory or a .mcap file)")
    if path.is_file() and path.suffix != ".mcap":
        raise DataError(f"{path}: not a bag (expected a rosbag2 directory or a single .mcap file)")
    if path.is_dir() and not (path / "metadata.yaml").exists() and not any(path.glob("*.mcap")):
        # --salvage would find nothing to read here; say what the directory is instead
        inner = sorted(d.name for d in path.iterdir() if d.is_dir() and ((d / "metadata.yaml").exists()
                                                                          or any(d.glob("*.mcap"))))
        if inner:
            shown = ", ".join(inner[:5]) + (", ..." if len(inner) > 5 else "")
            raise DataError(f"{path} is a folder of bags ({shown}); give one bag directory")
        raise DataError(f"{path}: not a bag (a rosbag2 directory holds metadata.yaml and .mcap files)")
    try:
        reader = AnyReader([path], default_typestore=_typestore())
        reader.open()
    except DataError:
        raise
    except Exception as err:  # rosbags raises several types for damaged bags; all mean "unreadable"
        raise DataError(f"{path}: cannot open bag ({type(err).__name__}: {err}); is it complete? (a recorder "
                        "stopped without finishing it: --salvage reads what it wrote)") from err
    return reader


def list_topics(path: str | Path) -> dict[str, tuple[str, int]]:
    """``{topic: (msgtype, message_count)}`` of a bag."""
    path = Path(path)
    reader = _open_reader(path)
    try:
        return {c.topic: (c.msgtype, int(c.msgcount)) for c in reader.connections}
    finally:
        reader.close()


def _pad(rows: list, k: int) -> np.ndarray:
    out = np.full((len(rows), k), np.nan)
    for i, r in enumerate(rows):
        if len(r):
            out[i, :len(r)] = r
    return out


def read_joint_states(path: str | Path, topic: str = STATE_TOPIC) -> JointStates:
    """Every ``sensor_msgs/msg/JointState`` message on ``topic`` of a bag.

    Raises
    ------
    DataError
        Missing bag or topic, wrong message type, no messages, or a damaged (truncated) bag.
    """
    path = Path(path)
    reader = _open_reader(path)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            have = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})) or "none"
            raise DataError(f"{path}: no topic {topic!r} in the bag (topics: {have}); choose one with --topic")
        wrong = [c.msgtype for c in conns if c.msgtype != _JS]
        if wrong:
            raise DataError(f"{path}: topic {topic!r} carries {wrong[0]}, expected {_JS}")
        stamps, logs, names, pos, vel, eff = [], [], [], [], [], []
        try:
            for conn, log_ns, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                stamps.append(int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec))
                logs.append(int(log_ns))
                names.append(list(msg.name))
                pos.append(np.asarray(msg.position, dtype=np.float64))
                vel.append(np.asarray(msg.velocity, dtype=np.float64))
                eff.append(np.asarray(msg.effort, dtype=np.float64))
        except Exception as err:  # truncated chunk, bad CDR, zstd error ...
            raise DataError(f"{path}: bag is damaged or truncated after {len(stamps)} message(s) on {topic!r} "
                            f"({type(err).__name__}: {err})") from err
    finally:
        reader.close()
    if not stamps:
        raise DataError(f"{path}: topic {topic!r} has no messages (empty bag?)")
    k = max((len(r) for r in pos + vel + eff), default=0)
    return JointStates(np.array(stamps, dtype=np.int64), np.array(logs, dtype=np.int64), names,
                       _pad(pos, k), _pad(vel, k), _pad(eff, k))


def salvage_joint_states(path: str | Path, topic: str = STATE_TOPIC) -> JointStates:
    """Read what a killed recorder left in an MCAP file without summary/footer (opt-in ``--salvage``).

    The file is read front to back with the ``mcap`` stream reader; every message of complete chunks on ``topic``
    is kept, reading stops at the first damaged record. ``path`` may be the ``.mcap`` file or a bag directory
    holding exactly one.
    """
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    p = Path(path)
    if p.is_dir():
        files = sorted(p.glob("*.mcap"))
        if len(files) != 1:
            raise DataError(f"{p}: salvage needs exactly one .mcap file in the bag, found {len(files)}")
        p = files[0]
    if not p.is_file():
        raise DataError(f"{path}: no such bag")
    ts = _typestore()
    chans: dict[int, str] = {}
    stamps, logs, names, pos, vel, eff = [], [], [], [], [], []
    with open(p, "rb") as fh:
        try:
            for rec in StreamReader(fh, skip_magic=False).records:
                if isinstance(rec, Channel):
                    chans[rec.id] = rec.topic
                elif isinstance(rec, Message) and chans.get(rec.channel_id) == topic:
                    msg = ts.deserialize_cdr(rec.data, _JS)
                    stamps.append(int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec))
                    logs.append(int(rec.log_time))
                    names.append(list(msg.name))
                    pos.append(np.asarray(msg.position, dtype=np.float64))
                    vel.append(np.asarray(msg.velocity, dtype=np.float64))
                    eff.append(np.asarray(msg.effort, dtype=np.float64))
        except Exception:  # noqa: BLE001 - the damaged tail: keep everything before it
            pass
    if not stamps:
        raise DataError(f"{path}: nothing on {topic!r} could be salvaged")
    k = max((len(r) for r in pos + vel + eff), default=0)
    return JointStates(np.array(stamps, dtype=np.int64), np.array(logs, dtype=np.int64), names,
                       _pad(pos, k), _pad(vel, k), _pad(eff, k))


def read_state_bag(path: str | Path, topic: str = STATE_TOPIC, *, salvage: bool = False) -> Record:
    """The stage state record (t in s from the first sample, u in V, y in m) from a bag.

    With ``salvage=True`` an MCAP bag that cannot be opened (a recorder killed before writing its footer) is read
    up to its damaged tail instead of failing; ``meta['salvaged']`` is then True.

    ``t`` comes from ``header.stamp`` (the sample time); if no message has its stamp set, the bag log time is
    used instead and ``meta['time_source']`` says so. Messages are ordered by time. Messages without
    ``position[0]``/``effort[0]`` become NaN rows, which :meth:`Record.check` reports.
    """
    salvaged = False
    try:
        js = read_joint_states(path, topic)
    except DataError as err:
        if not (salvage and "cannot open bag" in str(err)):
            raise
        js = salvage_joint_states(path, topic)
        salvaged = True
    if js.position.shape[1] == 0 or np.isnan(js.position[:, 0]).all():
        raise DataError(f"{path}: {topic!r} messages carry no position[0] (displacement, m)")
    if js.effort.shape[1] == 0 or np.isnan(js.effort[:, 0]).all():
        raise DataError(f"{path}: {topic!r} messages carry no effort[0] (applied voltage, V)")
    if (js.stamp_ns == 0).all():
        ns, source = js.log_ns, "log_time"
    else:
        ns, source = js.stamp_ns, "header.stamp"
    _one_run(path, topic, ns)
    order = np.argsort(ns, kind="stable")
    ns = ns[order]
    t0 = int(ns[0])
    t = (ns - t0).astype(np.float64) * 1e-9
    meta = {"source": str(path), "topic": topic, "t0_ns": t0, "time_source": source, "format": "rosbag2",
            "missing_values": int(np.isnan(js.position[:, 0]).sum() + np.isnan(js.effort[:, 0]).sum()),
            "salvaged": salvaged}
    return Record(t, js.effort[order, 0], js.position[order, 0], meta)


#: Stamps going back by more than this many periods in the order the bag holds them: another run, not reordering.
RESTART_PERIODS = 50


def _one_run(path, topic: str, ns: np.ndarray) -> None:
    """Refuse a bag whose stamps start over: a recorder kept across a restart of the stage holds two runs stamped
    from 0, which sorting by stamp spliced into one record (66 nm where each run fits at 2 nm; only a note on
    'repeated stamps with different values' said anything). Small steps back (delivery reordering) are sorted."""
    if ns.size < 3:
        return
    d = np.diff(ns.astype(np.int64))
    fwd = d[d > 0]
    if not fwd.size:
        return
    period = float(np.median(fwd))
    k = int(np.argmin(d))
    if -d[k] > RESTART_PERIODS * period:
        raise DataError(f"{path}: the {topic} stamps start over at message {k + 2} of {ns.size} (back by "
                        f"{-d[k] * 1e-9:.6g} s): the bag holds more than one run (a recorder kept running across a "
                        "restart of the stage?); record each run in its own bag")


def _joint_state(ts, stamp_ns: int, frame_id: str, names: Sequence[str], pos, vel, eff):
    from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
    from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__JointState as JointState
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return JointState(header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id), name=list(names),
                      position=np.asarray(pos, dtype=np.float64), velocity=np.asarray(vel, dtype=np.float64),
                      effort=np.asarray(eff, dtype=np.float64))


def _as_2d(a, n: int) -> np.ndarray:
    if a is None:
        return np.empty((n, 0))
    a = np.asarray(a, dtype=np.float64)
    return a.reshape(n, 1) if a.ndim == 1 else a.reshape(n, -1)


def write_state_bag(path: str | Path, t, u, y, topic: str = STATE_TOPIC, *,
                    extra: Mapping[str, Mapping] | None = None, t0_ns: int = 0, frame_id: str = "stage",
                    joint: str = "stage", storage: str = "mcap", compress: bool = True) -> Path:
    """Write ``t, u, y`` (s, V, m) as a JointState stream to a new rosbag2 (MCAP, zstd chunks) and return its path.

    Parameters
    ----------
    path : path
        New bag directory; a path ending in ``.mcap`` gives a single MCAP file instead. Never overwritten.
    t, u, y : array_like
        Sample time (s, ``header.stamp`` and log time = ``t0_ns + t``), applied voltage (``effort[0]``),
        displacement (``position[0]``). NaN values are written as they are (for testing readers).
    topic : str
        State topic.
    extra : mapping, optional
        More JointState topics: ``{topic: {"t": ..., "name": [...], "position": ..., "velocity": ...,
        "effort": ...}}``; value arrays are 1-D (one joint) or shape (n, joints); missing ones are empty.
    t0_ns : int
        Absolute time of t = 0 (ns).
    storage : {"mcap", "sqlite3"}
        Storage plugin (sqlite3 for testing the other reader path).
    compress : bool
        zstd chunk compression (MCAP only).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    path = Path(path)
    if path.exists():
        raise DataError(f"{path} exists; not overwriting a bag")
    single = path.suffix == ".mcap"
    if single and storage != "mcap":
        raise DataError("a single .mcap file needs storage='mcap'")
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}.get(storage)
    if plugin is None:
        raise DataError(f"unknown storage {storage!r}; use 'mcap' or 'sqlite3'")
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    streams: dict[str, dict] = {topic: {"t": t, "name": [joint], "position": y, "effort": u}}
    for tp, spec in (extra or {}).items():
        if tp in streams:
            raise DataError(f"topic {tp!r} given twice")
        streams[tp] = dict(spec)
    ts = _typestore()
    target = Path(tempfile.mkdtemp(prefix=".bag-", dir=path.parent)) / "bag" if single else path
    writer = Writer(target, version=9, storage_plugin=plugin)
    if compress and plugin == StoragePlugin.MCAP:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    try:
        with writer:
            for tp, spec in streams.items():
                tt = np.asarray(spec["t"], dtype=np.float64).ravel()
                n = tt.size
                pos, vel, eff = (_as_2d(spec.get(k), n) for k in ("position", "velocity", "effort"))
                names = list(spec.get("name") or [joint] * max(pos.shape[1], vel.shape[1], eff.shape[1], 1))
                conn = writer.add_connection(tp, _JS, typestore=ts)
                stamps = int(t0_ns) + np.round(tt * 1e9).astype(np.int64)
                for k in range(n):
                    msg = _joint_state(ts, stamps[k], frame_id, names, pos[k], vel[k], eff[k])
                    writer.write(conn, int(max(stamps[k], 0)), ts.serialize_cdr(msg, _JS))
        if single:
            files = list(target.glob("*.mcap"))
            shutil.move(str(files[0]), str(path))
    finally:
        if single:
            shutil.rmtree(target.parent, ignore_errors=True)
    return path
