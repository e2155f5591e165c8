"""CSV input/output in SI units.

The native format is a header ``t,u,y`` (s, V, m). Any other CSV is read by naming its three columns and their
units, e.g. for ../shared/data/piezo_150V_1Hz::

    read_csv(path, columns=("t_s", "voltage_V", "displacement_um"), units=("s", "V", "um"))

When ``units`` is omitted, a unit is taken from a column name's suffix (``displacement_um`` → µm) and SI is
assumed otherwise; ``meta['units']`` records what was used. Unknown columns or units are a
:class:`~hyst_model.errors.DataError` that names the choices.
"""
from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .modes import mkstemp_user
from ..errors import DataError
from .record import Record

__all__ = ["UNITS", "parse_list", "read_csv", "read_input_csv", "write_csv"]

#: Accepted units per quantity and their factor to SI. The input may be a voltage (PEA), a driver current (GMA)
#: or a force (the Bouc-Wen benchmark); it is never converted between those kinds.
UNITS: dict[str, dict[str, float]] = {
    "t": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9},
    "u": {"V": 1.0, "mV": 1e-3, "kV": 1e3, "A": 1.0, "mA": 1e-3, "N": 1.0},
    "y": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9},
}
_SI = {"t": "s", "u": "V", "y": "m"}


def parse_list(text: str | Sequence[str] | None, what: str, quantities: str = "tuy") -> tuple[str, ...] | None:
    """``"a,b,c"`` → ``("a", "b", "c")``; checks there is one entry per quantity (t,u,y by default)."""
    if text is None:
        return None
    items = tuple(s.strip() for s in (text.split(",") if isinstance(text, str) else text))
    if len(items) != len(quantities) or not all(items):
        raise DataError(f"{what} needs {len(quantities)} comma-separated entries for {','.join(quantities)} "
                        f"(got {','.join(items)!r})")
    return items


def _unit_factor(q: str, unit: str) -> float:
    try:
        return UNITS[q][unit]
    except KeyError:
        raise DataError(f"unknown unit {unit!r} for {q} ({'time' if q == 't' else 'input' if q == 'u' else 'output'}"
                        f"); use one of {', '.join(UNITS[q])}") from None


def _suffix_unit(q: str, col: str) -> str:
    tail = col.rsplit("_", 1)[-1] if "_" in col else ""
    return tail if tail in UNITS[q] else _SI[q]


def _read_columns(path: Path, columns: tuple[str, ...], units: tuple[str, ...] | None, quantities: str):
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise DataError(f"{path}: cannot read ({err})") from err
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise DataError(f"{path}: empty file (expected a header row such as {','.join(quantities)})")
    header = [h.strip() for h in lines[0].split(",")]
    if all(len(h) >= 2 and h[0] == h[-1] == '"' for h in header):  # "t","u","y": a spreadsheet's quoting
        header = [h[1:-1].strip() for h in header]
    roles = [c for c in columns if columns.count(c) > 1]
    if roles:  # --columns t,t,y read the time as the voltage, silently
        raise DataError(f"{path}: --columns names {roles[0]} for more than one of {', '.join(quantities)}; "
                        "name one column for each")
    twice = [c for c in columns if header.count(c) > 1]
    if twice:  # which one is meant cannot be known: the first was taken, silently
        raise DataError(f"{path}: the header has the column {twice[0]} more than once; rename one of them")
    missing = [c for c in columns if c not in header]
    if missing:
        hint = (" (name the columns with --columns and their units with --units)"
                if tuple(columns) == tuple(quantities) else "")
        other = next((d for d in (";", "\t", "|") if d in lines[0]), None)
        if other is not None and len(header) == 1:  # told to name the columns, which does not help
            raise DataError(f"{path}: the header is separated by {other!r}; hyst reads comma-separated CSV "
                            f"(replace the separator with ',')")
        raise DataError(f"{path}: column(s) {', '.join(missing)} not in the header {','.join(header)}{hint}")
    if units:  # a unit the column's own name contradicts (y_um read as nm: 1000x off, silently)
        for q, c, un in zip(quantities, columns, units):
            named = _suffix_unit(q, c)
            if "_" in c and c.rsplit("_", 1)[-1] in UNITS[q] and UNITS[q][named] != _unit_factor(q, un):
                raise DataError(f"{path}: column {c} says {named} but --units gives {un}; rename the column or "
                                "drop --units (the suffix is read when --units is not given)")
    us = units or tuple(_suffix_unit(q, c) for q, c in zip(quantities, columns))
    factors = np.array([_unit_factor(q, un) for q, un in zip(quantities, us)])
    idx = [header.index(c) for c in columns]
    if len(lines) < 2 or not any(ln.strip() for ln in lines[1:]):
        raise DataError(f"{path}: header only, no data rows")
    width = len(header)
    for k, ln in enumerate(lines[1:], start=2):  # a row with a field too many was cut silently, one too few
        if ln.strip() and ln.count(",") + 1 != width:  # came as numpy's two-line "Some errors were detected !"
            raise DataError(f"{path}: malformed rows (line {k} has {ln.count(',') + 1} fields, the header "
                            f"{width})")
    try:
        data = np.genfromtxt(io.StringIO(text), delimiter=",", skip_header=1, usecols=idx, dtype=np.float64,
                             invalid_raise=True, encoding="utf-8-sig")
    except ValueError as err:
        raise DataError(f"{path}: malformed rows ({err})") from err
    data = np.asarray(data, dtype=np.float64).reshape(-1, len(columns)) * factors
    return data, list(us)


def read_csv(path: str | Path, columns: Sequence[str] | str | None = None,
             units: Sequence[str] | str | None = None) -> Record:
    """Read a CSV file into a :class:`Record` in SI units.

    Parameters
    ----------
    path : path
        CSV with a header row; comma separated.
    columns : three names, optional
        Header names of the time, input and output columns; default ``t,u,y``.
    units : three units, optional
        Units of those columns (see :data:`UNITS`); default from the name suffix, else SI.

    Raises
    ------
    DataError
        Missing file, no header, unknown column or unit, non-numeric values.
    """
    path = Path(path)
    columns = parse_list(columns, "--columns") or ("t", "u", "y")
    data, us = _read_columns(path, columns, parse_list(units, "--units"), "tuy")
    meta = {"source": str(path), "format": "csv", "columns": list(columns), "units": us}
    return Record(data[:, 0], data[:, 1], data[:, 2], meta)


def read_input_csv(path: str | Path, columns: Sequence[str] | str | None = None,
                   units: Sequence[str] | str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read an input-only CSV (``t,u`` by default) and return ``(t, u)`` in s and V, checked finite and increasing."""
    path = Path(path)
    columns = parse_list(columns, "--columns", "tu") or ("t", "u")
    data, _ = _read_columns(path, columns, parse_list(units, "--units", "tu"), "tu")
    t, u = data[:, 0], data[:, 1]
    bad = ~(np.isfinite(t) & np.isfinite(u))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise DataError(f"{path}: {int(bad.sum())} row(s) with NaN/inf values (first at data row {k})")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise DataError(f"{path}: time not strictly increasing at data row {k + 1}")
    return t, u


def write_csv(path: str | Path, columns: Mapping[str, np.ndarray], *, force: bool = False,
              header_comment: str | None = None) -> Path:
    """Write equal-length columns to a CSV atomically; refuse to overwrite without ``force``.

    Parameters
    ----------
    path : path
        Target file.
    columns : mapping
        Column name → values (SI units; the names go into the header row in order).
    force : bool
        Replace an existing file.
    header_comment : str, optional
        Not written into the CSV (kept machine-readable); reserved for callers that log provenance.
    """
    path = Path(path)
    if path.exists() and not force:
        raise DataError(f"{path} exists; use --force to overwrite it")
    if path.is_dir():
        raise DataError(f"{path} is a directory")
    names = list(columns)
    arr = np.column_stack([np.asarray(columns[n], dtype=np.float64).ravel() for n in names])
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise DataError(f"{parent}: no such directory")
    fd, tmp = mkstemp_user(prefix=f".{path.name}.", dir=parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(",".join(names) + "\n")
            np.savetxt(fh, arr, delimiter=",", fmt="%.10g")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
