"""IO adapters: rosbag2 (``rosbags``), CSV and params files. Everything returns/accepts SI units.

:func:`load_record` is the one entry point the command line and the nodes use to turn a path into a
:class:`Record`: a rosbag2 directory or ``.mcap`` file goes through :mod:`.bag`, anything else through :mod:`.csvio`.
"""
from __future__ import annotations

from pathlib import Path

from .bag import STATE_TOPIC, JointStates, list_topics, read_joint_states, read_state_bag, write_state_bag
from .csvio import UNITS, read_csv, write_csv
from .params_file import ParamsSpec, read_params, spec_from_model, write_params
from .record import Record
from .regular import GAP_POLICIES, regularise

__all__ = [
    "GAP_POLICIES", "regularise",
    "Record", "load_record", "is_bag",
    "STATE_TOPIC", "JointStates", "list_topics", "read_joint_states", "read_state_bag", "write_state_bag",
    "UNITS", "read_csv", "write_csv",
    "ParamsSpec", "read_params", "spec_from_model", "write_params",
]


def is_bag(path: str | Path) -> bool:
    """True for a directory (a rosbag2 bag) or a ``.mcap`` file."""
    p = Path(path)
    if p.is_dir():
        return True  # a directory can only be a bag; the reader says what is missing in it
    return p.suffix == ".mcap"


def load_record(path: str | Path, *, topic: str = STATE_TOPIC, columns=None, units=None,
                salvage: bool = False) -> Record:
    """Read a bag or a CSV file into a :class:`Record` (not yet checked: call :meth:`Record.check`)."""
    from ..errors import DataError
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file or bag")
    if is_bag(p):
        if columns is not None or units is not None:
            raise DataError(f"{p}: --columns/--units apply to CSV files, not bags (bags are SI by contract)")
        return read_state_bag(p, topic, salvage=salvage)
    if topic != STATE_TOPIC or salvage:  # ignored silently before, as --columns on a bag never was
        raise DataError(f"{p}: --topic and --salvage apply to bags, not CSV files (name CSV columns with --columns)")
    return read_csv(p, columns, units)
