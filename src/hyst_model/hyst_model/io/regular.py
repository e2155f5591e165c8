"""Make a recorded run regular as the rig produced it: lockstep duplicate stamps collapsed, missed periods
bridged or split off (issue 11). Pure numpy; used by ``hyst fit|compare|diagnose`` and the identification node."""
from __future__ import annotations

import numpy as np

from ..errors import DataError
from .record import Record

__all__ = ["regularise", "GAP_MODES", "BRIDGE_MAX_PERIODS"]

GAP_MODES = ("auto", "bridge", "longest", "refuse")
#: Longest gap ``auto`` bridges, in missed sample periods: over a few periods the DAC holds the voltage and the
#: stage moves little, so holding u and interpolating y is faithful; beyond that the record is split.
BRIDGE_MAX_PERIODS = 5
_MAX_GAP = 1.5  # a step above this many median periods is a gap (as Record.check)


def _collapse_duplicates(rec: Record) -> tuple[Record, int]:
    d = np.diff(rec.t)
    if (d < 0).any():
        k = int(np.flatnonzero(d < 0)[0])
        raise DataError(f"{rec.source}: time stamps go backwards at row {k + 1} (t={rec.t[k]:.9g} then "
                        f"{rec.t[k + 1]:.9g} s); sort or cut the record")
    keep = np.ones(len(rec), dtype=bool)
    keep[1:] = d > 0  # the first copy of a repeated stamp is the sample; later copies are re-publications
    n = int((~keep).sum())
    if n == 0:
        return rec, 0
    return Record(rec.t[keep], rec.u[keep], rec.y[keep], dict(rec.meta)), n


def _bridge(rec: Record, dt: float, gaps: np.ndarray) -> Record:
    t_parts, u_parts, y_parts = [], [], []
    start = 0
    for k in gaps:
        t_parts.append(rec.t[start:k + 1])
        u_parts.append(rec.u[start:k + 1])
        y_parts.append(rec.y[start:k + 1])
        m = int(round((rec.t[k + 1] - rec.t[k]) / dt)) - 1
        tf = rec.t[k] + dt * np.arange(1, m + 1)
        t_parts.append(tf)
        u_parts.append(np.full(m, rec.u[k]))  # the DAC holds the last voltage
        y_parts.append(np.interp(tf, rec.t[k:k + 2], rec.y[k:k + 2]))
        start = k + 1
    t_parts.append(rec.t[start:])
    u_parts.append(rec.u[start:])
    y_parts.append(rec.y[start:])
    return Record(np.concatenate(t_parts), np.concatenate(u_parts), np.concatenate(y_parts), dict(rec.meta))


def regularise(rec: Record, gaps: str = "auto") -> tuple[Record, list[str]]:
    """Return a regularly sampled record and human-readable notes on what was changed.

    Parameters
    ----------
    rec : Record
        As read from a bag or CSV (finite values; stamps non-decreasing).
    gaps : {"auto", "bridge", "longest", "refuse"}
        Missed sample periods: ``bridge`` fills every gap (u held, y interpolated); ``longest`` keeps the longest
        regular stretch; ``refuse`` raises :class:`DataError`; ``auto`` bridges gaps of at most
        :data:`BRIDGE_MAX_PERIODS` periods and keeps the longest stretch between longer ones.

    Returns
    -------
    (Record, list of str)
        ``meta["regularised"]`` holds the counts (duplicates, bridged, split) for reports/JSON.
    """
    if gaps not in GAP_MODES:
        raise DataError(f"unknown gap handling {gaps!r}; choose one of {', '.join(GAP_MODES)}")
    notes: list[str] = []
    info = {"gaps": gaps, "duplicates": 0, "bridged_gaps": 0, "bridged_samples": 0, "dropped_samples": 0}
    if len(rec) < 2 or not np.isfinite(rec.t).all():
        return rec, notes  # Record.check reports these with the row
    rec, ndup = _collapse_duplicates(rec)
    if ndup:
        info["duplicates"] = ndup
        notes.append(f"collapsed {ndup} sample(s) with a repeated time stamp (lockstep re-publication)")
    if len(rec) < 2:
        return rec, notes
    d = np.diff(rec.t)
    dt = float(np.median(d))
    gap_idx = np.flatnonzero(d > _MAX_GAP * dt)
    if gap_idx.size:
        missed = np.rint(d[gap_idx] / dt).astype(int) - 1
        if gaps == "refuse":
            k = int(gap_idx[0])
            raise DataError(f"{rec.source}: {gap_idx.size} gap(s) in the time stamps (first after t={rec.t[k]:.6f} s:"
                            f" {d[k] * 1e3:.3f} ms vs a {dt * 1e3:.3f} ms sample period); samples were lost — "
                            "use --gaps auto|bridge|longest")
        short = gap_idx if gaps == "bridge" else (
            gap_idx[missed <= BRIDGE_MAX_PERIODS] if gaps == "auto" else gap_idx[:0])
        if short.size:
            nfill = int(np.rint(d[short] / dt).sum()) - short.size
            rec = _bridge(rec, dt, short)
            info.update(bridged_gaps=int(short.size), bridged_samples=nfill)
            notes.append(f"bridged {short.size} gap(s) of missed periods ({nfill} sample(s): u held, y interpolated)")
        if short.size < gap_idx.size:
            n0 = len(rec)
            rec = rec.longest_segment(max_gap=_MAX_GAP)
            a, b = rec.meta["segment"]
            info["dropped_samples"] = n0 - (b - a)
            notes.append(f"{gap_idx.size - short.size} long gap(s): kept the longest regular segment "
                         f"(samples {a}–{b}, dropped {n0 - (b - a)})")
    rec.meta["regularised"] = info
    return rec, notes
