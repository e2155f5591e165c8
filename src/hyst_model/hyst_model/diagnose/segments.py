"""Where a record's input changes character: holds, steps, sines by frequency (:func:`segment_input`), and the fit
figures per segment (:func:`fit_by_segment`), so a comparison can say *where* the model fails. Pure numpy; part of
:mod:`.stats`, which re-exports everything here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .figures import Fit, _as_1d, fit_figures, noise_sigma

__all__ = ["Segment", "SegmentFit", "segment_input", "fit_by_segment"]


@dataclass(frozen=True)
class Segment:
    """A stretch of the input with one character.

    Attributes
    ----------
    kind : str
        ``"hold"`` (input constant), ``"step"`` (a jump between holds, its first samples), ``"sine"`` (periodic
        motion at ``freq``), ``"broadband"`` (the whole record when it is a multisine/noise/fast sweep), or
        ``"motion"`` (anything else: ramps, transients).
    start, stop : int
        Sample range ``[start, stop)``.
    freq : float
        Dominant frequency (Hz) for sines, NaN otherwise.
    level : float
        Mean input over the segment (V).
    """

    kind: str
    start: int
    stop: int
    freq: float = float("nan")
    level: float = float("nan")

    @property
    def label(self) -> str:
        if self.kind == "sine":
            return f"sine {self.freq:.3g} Hz"
        if self.kind in ("hold", "step"):
            return f"{self.kind} {self.level:.4g}"
        return self.kind


@dataclass(frozen=True)
class SegmentFit:
    """Fit figures of one :class:`Segment` (times in s)."""

    label: str
    kind: str
    t0: float
    t1: float
    freq: float
    fit: Fit

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "kind": self.kind, "t0": self.t0, "t1": self.t1,
                "freq": None if not np.isfinite(self.freq) else self.freq, **self.fit.to_dict()}


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs of True as ``(start, stop)`` pairs."""
    m = np.concatenate(([False], mask.astype(bool), [False]))
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return list(zip(d[0::2].tolist(), d[1::2].tolist()))


def _hold_mask(u: np.ndarray, fs: float, min_hold_s: float, tol: float | None) -> np.ndarray:
    span = float(np.ptp(u)) if u.size else 0.0
    if tol is None:
        # Quantisation and noise make |du| of a held input non-zero; 6 σ of the difference noise is safe. The
        # cap keeps a broadband input (content up to Nyquist looks like "noise" to noise_sigma) from being a hold.
        tol = max(min(6.0 * np.sqrt(2.0) * noise_sigma(u), 0.005 * span), 1e-9 * max(span, 1e-300))
    du = np.abs(np.diff(u, prepend=u[:1]))
    still = du <= tol
    still[0] = still[1] if u.size > 1 else True
    min_len = max(5, int(round(min_hold_s * fs)))
    hold = np.zeros(u.size, bool)
    for a, b in _runs(still):
        if b - a >= min_len:
            hold[a:b] = True
    return hold


def _schmitt_crossings(x: np.ndarray, h: float) -> np.ndarray:
    """Indices where ``x`` passes +h after having been below −h, or −h after having been above +h."""
    up = x > h
    down = x < -h
    idx = np.flatnonzero(up | down)
    if idx.size == 0:
        return idx
    state = up[idx]
    flips = np.flatnonzero(state[1:] != state[:-1]) + 1
    out = idx[flips]
    return out[out > 0]


def _split_by_period(u: np.ndarray, a: int, b: int, fs: float, tol: float) -> list[Segment]:
    """Split a moving stretch ``[a, b)`` into sine segments of near-constant period (midline crossings)."""
    x = u[a:b]
    mid = 0.5 * (np.max(x) + np.min(x))
    # Schmitt trigger around the midline: input noise must not make extra crossings.
    h = max(3.0 * noise_sigma(x), 0.01 * float(np.ptp(x)))
    cross = _schmitt_crossings(x - mid, h)  # sample index (relative) at or after each crossing
    if cross.size < 4:  # fewer than 1.5 cycles: no frequency to speak of
        return [Segment("motion", a, b, level=float(np.mean(x)))]
    # Sub-sample crossing times (linear interpolation through the threshold) for the frequency estimate.
    sign = np.where(x[cross] - mid > 0, 1.0, -1.0)
    xa, xb = x[cross - 1] - mid - sign * h, x[cross] - mid - sign * h
    frac = np.where(xb != xa, xa / (xa - xb), 0.5)
    half = np.diff(cross - 1 + np.clip(frac, 0.0, 1.0))
    # Group consecutive half-periods whose length stays within tol of the running group median.
    groups: list[list[int]] = [[0]]
    for i in range(1, half.size):
        g = groups[-1]
        med = float(np.median(half[g]))
        if abs(half[i] - med) <= tol * med:
            g.append(i)
        else:
            groups.append([i])
    out: list[Segment] = []
    cursor = a
    for g in groups:
        g0, g1 = g[0], g[-1]
        seg_a = a + int(cross[g0])
        seg_b = a + int(cross[g1 + 1])
        if len(g) >= 3:  # at least 1.5 periods
            if seg_a > cursor:
                out.append(Segment("motion", cursor, seg_a, level=float(np.mean(u[cursor:seg_a]))))
            freq = fs / (2.0 * float(np.mean(half[g])))
            out.append(Segment("sine", seg_a, seg_b, freq=freq, level=float(np.mean(u[seg_a:seg_b]))))
            cursor = seg_b
    if cursor < b:
        if out and out[-1].kind == "sine" and b - cursor < 0.5 * (out[-1].stop - out[-1].start) / 2:
            last = out.pop()  # a short tail belongs to the sine before it
            out.append(Segment("sine", last.start, b, last.freq, float(np.mean(u[last.start:b]))))
        else:
            out.append(Segment("motion", cursor, b, level=float(np.mean(u[cursor:b]))))
    return out


def segment_input(t: np.ndarray, u: np.ndarray, *, min_hold_s: float = 0.05, step_s: float | None = None,
                  tol: float | None = None, period_tol: float = 0.2, max_segments: int = 40) -> list[Segment]:
    """Cut an input record into holds, steps, sines (by frequency) and other motion.

    Parameters
    ----------
    t, u : ndarray
        Sample times (s) and input (V).
    min_hold_s : float
        A stretch of constant input shorter than this is not a hold.
    step_s : float, optional
        How long after a jump the response counts as the "step" segment (transient) before the "hold"; default
        a fifth of the hold, at most 0.5 s.
    tol : float, optional
        Largest per-sample input change that still counts as constant (V); default from the input's noise.
    period_tol : float
        Relative change of half-period that starts a new sine segment (a frequency change).
    max_segments : int
        More segments than this, mostly shorter than 0.5 s, means a broadband input: one ``"broadband"`` segment.

    Returns
    -------
    list of Segment
        Contiguous and covering ``[0, len(u))`` in order.
    """
    t = _as_1d("t", t)
    u = _as_1d("u", u)
    n = u.size
    if n < 2:
        return [Segment("motion", 0, n, level=float(np.mean(u)) if n else float("nan"))]
    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt if dt > 0 else 1.0
    hold = _hold_mask(u, fs, min_hold_s, tol)
    span = float(np.ptp(u))
    out: list[Segment] = []
    pos = 0
    for a, b in _runs(hold) + [(n, n)]:
        if a > pos:
            moving = _split_by_period(u, pos, a, fs, period_tol)
            if pos > 0 and abs(u[pos] - u[pos - 1]) > 0.02 * span and moving[0].kind == "motion":
                moving[0] = Segment("step", moving[0].start, moving[0].stop, level=moving[0].level)
            out.extend(moving)
        if b > a:
            level = float(np.mean(u[a:b]))
            # A hold reached by a jump (within a few samples) starts with a step response.
            is_step = a > 0 and abs(level - u[max(a - 4, 0)]) > 0.02 * span
            if is_step:
                n_step = int(round((step_s if step_s is not None else min(0.5, 0.2 * (b - a) * dt)) * fs))
                n_step = max(1, min(n_step, b - a - 1))
                start = a
                if out and out[-1].kind == "motion" and out[-1].stop - out[-1].start <= 4:
                    start = out.pop().start  # the jump samples belong to the step
                out.append(Segment("step", start, a + n_step, level=level))
                if a + n_step < b:
                    out.append(Segment("hold", a + n_step, b, level=level))
            else:
                out.append(Segment("hold", a, b, level=level))
        pos = b
    # Merge neighbours of the same kind (and the same frequency for sines).
    merged: list[Segment] = []
    for s in out:
        if s.stop <= s.start:
            continue
        if merged and merged[-1].kind == s.kind and s.kind in ("motion",):
            p = merged.pop()
            s = Segment(s.kind, p.start, s.stop, level=float(np.mean(u[p.start:s.stop])))
        merged.append(s)
    if len(merged) > max_segments and np.median([s.stop - s.start for s in merged]) * dt < 0.5:
        # Broadband input (multisine, noise, fast sweep): pieces of a few samples say nothing; one segment.
        return [Segment("broadband", 0, n, level=float(np.mean(u)))]
    return merged


def fit_by_segment(t: np.ndarray, u: np.ndarray, y: np.ndarray, yhat: np.ndarray,
                   segments: list[Segment] | None = None, **kw) -> list[SegmentFit]:
    """Fit figures per input segment (:func:`segment_input` unless ``segments`` is given)."""
    t = _as_1d("t", t)
    segs = segment_input(t, u, **kw) if segments is None else segments
    return [SegmentFit(s.label, s.kind, float(t[s.start]), float(t[s.stop - 1]), s.freq,
                       fit_figures(y[s.start:s.stop], yhat[s.start:s.stop])) for s in segs]
