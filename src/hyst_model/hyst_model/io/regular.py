"""Make a rig's record regular as it comes: collapse repeated stamps, bridge or cut gaps, and say what was done.

Two artefacts of a live rig make a record irregular, and neither is the user's fault:

* **Repeated stamps.** The lockstep sim (and a driver re-sending its first sample until it is answered)
  publishes sample 0 several times with the same stamp; the recorder keeps every copy. Copies at one stamp are
  one sample: the last copy is kept (it is the newest reading of that instant), and the count is reported.
* **Missed periods.** A real-time sampler that falls behind publishes nothing for a few periods, while the
  stage keeps moving under the voltage the DAC holds. Over such a gap the input is known exactly (held), so a
  short gap is *bridged*: the missing sample times are put back on the grid with ``u`` held and ``y``
  interpolated linearly (those few ``y`` values are estimates; ``meta['bridged']`` holds their indices).
  A long gap (more than ``max_bridge`` periods) is not bridged: the record is cut there and the regular segment
  whose input varies most is kept (the longest is often the rest after the excitation: nothing to identify).

Time running backwards is never repaired (it means a merged or corrupted file) and stays an error.
"""
from __future__ import annotations

import numpy as np

from ..errors import DataError
from .record import Record

__all__ = ["GAP_POLICIES", "regularise"]

#: ``auto``: bridge gaps of at most ``max_bridge`` periods, keep the segment between longer ones whose input varies
#: most;
#: ``bridge``: the same, but a longer gap is an error; ``longest``: keep the longest regular segment;
#: ``refuse`` (alias ``error``): any gap or repeated stamp is an error.
GAP_POLICIES = ("auto", "bridge", "longest", "refuse", "error")


def _collapse_repeats(rec: Record, notes: list[str]) -> Record:
    d = np.diff(rec.t)
    if (d < 0).any():
        k = int(np.flatnonzero(d < 0)[0])
        raise DataError(f"{rec.source}: time runs backwards at row {k + 1} (t={rec.t[k]:.9g} then "
                        f"{rec.t[k + 1]:.9g} s); sort or cut the record first")
    rep = np.flatnonzero(d == 0)
    if rep.size == 0:
        return rec
    keep = np.ones(len(rec), dtype=bool)
    keep[rep] = False            # of a run of equal stamps keep the last copy
    differ = int(np.sum((rec.u[rep] != rec.u[rep + 1]) | (rec.y[rep] != rec.y[rep + 1])))
    if differ > max(10, 0.01 * len(rec)):  # copies of a re-sent sample are identical; this many are not copies
        raise DataError(f"{rec.source}: {differ} samples share their time stamp with another of different values: "
                        "two runs stamped alike in one record (a recorder kept across a restart of the stage?) or "
                        "corrupt stamps; record each run on its own")
    what = f"; {differ} of them with different values (kept the newest)" if differ else " (identical copies)"
    notes.append(f"collapsed {rep.size} repeated time stamp(s){what}")
    out = Record(rec.t[keep], rec.u[keep], rec.y[keep], dict(rec.meta))
    out.meta["collapsed_repeats"] = int(rep.size)
    return out


def _bridge(rec: Record, dt: float, gaps: np.ndarray, notes: list[str]) -> Record:
    """Put back the sample times of the given gaps (indices into diff(t)): u held, y interpolated."""
    ts, us, ys, bridged = [rec.t], [rec.u], [rec.y], []
    for k in gaps:
        m = int(round((rec.t[k + 1] - rec.t[k]) / dt)) - 1
        if m < 1:
            continue
        tt = rec.t[k] + dt * np.arange(1, m + 1)
        ts.append(tt)
        us.append(np.full(m, rec.u[k]))
        ys.append(np.interp(tt, rec.t[k:k + 2], rec.y[k:k + 2]))
        bridged.append(m)
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    is_new = np.zeros(t.size, dtype=bool)
    is_new[len(rec):] = True
    if "bridged" in rec.meta:  # samples an earlier pass put back stay marked
        is_new[np.asarray(rec.meta["bridged"], dtype=int)] = True
    out = Record(t[order], np.concatenate(us)[order], np.concatenate(ys)[order], dict(rec.meta))
    out.meta["bridged"] = np.flatnonzero(is_new[order]).tolist()
    notes.append(f"bridged {len(bridged)} gap(s) of missed periods ({sum(bridged)} samples, longest "
                 f"{max(bridged)}): input held as the DAC holds it, displacement interpolated")
    return out


def regularise(rec: Record, gaps: str = "auto", *, max_gap: float = 1.5, max_bridge: int = 10
               ) -> tuple[Record, list[str]]:
    """Return a regularly sampled copy of ``rec`` and notes saying what was changed.

    Parameters
    ----------
    rec : Record
        Finite samples in SI units (non-finite rows are an error, as in :meth:`Record.check`).
    gaps : {'auto', 'bridge', 'longest', 'refuse', 'error'}
        Policy for missed periods and repeated stamps (see :data:`GAP_POLICIES`).
    max_gap : float
        A step between stamps above this many median periods is a gap.
    max_bridge : int
        Longest gap, in missed samples, that is bridged.

    Returns
    -------
    (Record, list of str)
        The regular record (``meta['bridged']``: indices of bridged samples; ``meta['segment']`` when cut) and
        one line per change, empty when the record was regular already.

    Raises
    ------
    DataError
        Time running backwards, or an irregularity the policy does not allow (the message names the option).
    """
    if gaps not in GAP_POLICIES:
        raise DataError(f"unknown gap policy {gaps!r}; one of {', '.join(GAP_POLICIES)}")
    notes: list[str] = []
    if len(rec) < 2 or not np.isfinite(rec.t).all():
        return rec, notes                        # Record.check() gives the clear error for these
    if gaps in ("refuse", "error"):
        return rec.check(max_gap=max_gap), notes
    rec = _collapse_repeats(rec, notes)
    if gaps == "longest":
        cut = rec.longest_segment(max_gap=max_gap)
        if cut.meta.get("dropped_samples"):
            a, b = cut.meta["segment"]
            notes.append(f"kept the longest regular segment, samples {a}–{b} (dropped {cut.meta['dropped_samples']})")
        return cut, notes
    d = np.diff(rec.t)
    dt = float(np.median(d))
    gap_idx = np.flatnonzero(d > max_gap * dt)
    if gap_idx.size == 0:
        return rec, notes
    missed = np.rint(d[gap_idx] / dt).astype(int) - 1
    long_ = gap_idx[missed > max_bridge]
    if long_.size and gaps == "bridge":
        k = int(long_[0])
        raise DataError(f"{rec.source}: a gap of {d[k] * 1e3:.3f} ms after t={rec.t[k]:.6f} s is longer than "
                        f"{max_bridge} periods and cannot be bridged; use --gaps longest or --gaps auto")
    short = gap_idx[missed <= max_bridge]
    if short.size:
        rec = _bridge(rec, dt, short, notes)
    if long_.size:
        cut = rec.longest_segment(max_gap=max_gap, by="variation")
        a, b = cut.meta["segment"]
        notes.append(f"{long_.size} gap(s) longer than {max_bridge} periods: kept the regular segment whose input "
                     f"varies most, samples {a}–{b} of {len(rec)}")
        if "bridged" in rec.meta:
            br = np.asarray(rec.meta["bridged"], dtype=int)
            cut.meta["bridged"] = (br[(br >= a) & (br < b)] - a).tolist()
        rec = cut
    # A step just over the limit is a gap by the median of the record as it is now, which the bridging or the cut
    # moved: jittered stamps of a real-time run left a 1.5-period step that the whole record's median called
    # regular and the kept segment's median (what Record.check then uses) called a gap. Bridged by that median.
    for _ in range(3):
        d = np.diff(rec.t)
        med = float(np.median(d))
        late = np.flatnonzero(d > max_gap * med)
        late = late[np.rint(d[late] / med) - 1 <= max_bridge]
        if late.size == 0:
            break
        rec = _bridge(rec, med, late, notes)
    return rec, notes
