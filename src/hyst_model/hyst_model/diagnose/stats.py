"""Fit figures and residual tests for comparing a model with measurements (pure numpy/scipy).

Everything ``hyst compare`` and ``hyst diagnose`` say about *where* a model fails comes from here (the fit
figures live in :mod:`.figures` and the correlation tests in :mod:`.correlation`; both are re-exported here):

* fit figures (:class:`Fit`: RMSE, NRMSE, fit %, bias, max error) overall and broken down by time segment
  (holds, steps, sines by frequency; :func:`segment_input`), by branch (rising/falling input), by input level
  and by frequency band;
* residual whiteness (autocorrelation) and residual–input cross-correlation with 99 % confidence bounds, as
  MATLAB's ``resid`` draws them (:func:`autocorr`, :func:`crosscorr`);
* higher-order correlation tests in the style of Billings & Voon (1986) that reveal *even-order* structure the
  linear tests miss (an asymmetric loop, a quadratic gain, a rate-dependent error): corr(ε², u), corr(ε, u²),
  corr(ε, |du|), corr(ε², u²) (:func:`higher_order_tests`).

Definitions
-----------
With measured ``y``, model output ``ŷ`` and residual ``ε = y − ŷ`` (metres):

* ``rmse = sqrt(mean(ε²))``;
* ``nrmse = rmse / (max(y) − min(y))`` (normalised by the measured span, dimensionless);
* ``fit_percent = 100 (1 − ‖ε‖ / ‖y − mean(y)‖)``, MATLAB ``compare``'s NRMSE fit (100 = perfect, can be < 0);
* normalised correlation ``r_ab(τ) = Σ_k a'_k b'_{k−τ} / sqrt(Σ a'² Σ b'²)`` with means removed (primes), so
  ``r_ab(τ) > 0`` at ``τ > 0`` means ``a`` follows ``b`` with delay τ.

Confidence bounds (per lag, two-sided): the autocorrelation of a white residual is ~N(0, 1/N), bound
``z/sqrt(N)`` (z = 2.576 for 99 %). The cross-correlation of a residual independent of the input has variance
``P/N`` with ``P = Σ_k r_ε(k) r_u(k)`` (Ljung, *System Identification*, 2nd ed., §16.6), estimated over
``|k| ≤ L`` with a Bartlett window so that it is never negative; the bound is ``z sqrt(P/N)``. The higher-order
tests use ``z/sqrt(N)`` like Billings & Voon.

Lags are in samples times ``lag_step``. Lab records are heavily oversampled (2 kHz for a 1 Hz sine), so
25 single-sample lags would only look 12 ms back; :func:`compare_stats` therefore picks ``lag_step`` so the
lags span a useful part of the record (see its docstring). Each lag still uses all N samples, so the bounds hold.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .correlation import Correlation, auto_lag_step, autocorr, crosscorr, higher_order_tests, z_value
from .figures import Fit, _as_1d, fit_figures, noise_sigma

__all__ = [
    "Fit", "Segment", "SegmentFit", "Band", "Correlation", "CompareStats",
    "fit_figures", "noise_sigma", "segment_input", "fit_by_segment", "fit_by_branch", "fit_by_level",
    "fit_by_band", "loop_orientation", "harmonics", "ringing", "spectral_peaks", "autocorr", "crosscorr",
    "higher_order_tests", "auto_lag_step", "compare_stats", "z_value",
]


# -------------------------------------------------------------------------------------------------- segments
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


def fit_by_branch(u: np.ndarray, y: np.ndarray, yhat: np.ndarray, tol: float | None = None) -> dict[str, Fit]:
    """Fit figures on the rising (du > tol), falling (du < −tol) and held input samples.

    The residual's difference between branches shows a loop that is too wide, too narrow or tilted.
    """
    u = _as_1d("u", u)
    if tol is None:
        span = float(np.ptp(u)) if u.size else 0.0
        tol = max(min(6.0 * np.sqrt(2.0) * noise_sigma(u), 0.005 * span), 1e-12 * span)
    du = np.diff(u, prepend=u[:1])
    if du.size > 1:
        du[0] = du[1]  # the first sample has no predecessor: give it its neighbour's direction
    masks = {"rising": du > tol, "falling": du < -tol, "hold": np.abs(du) <= tol}
    return {k: fit_figures(np.asarray(y)[m], np.asarray(yhat)[m]) for k, m in masks.items()}


def fit_by_level(u: np.ndarray, y: np.ndarray, yhat: np.ndarray, n_levels: int = 5) -> list[tuple[float, float, Fit]]:
    """Fit figures per input-level bin: ``[(u_lo, u_hi, Fit), ...]`` with equal-width bins over the input range.

    A residual that grows with level shows a gain or saturation error; one that differs at the two ends of a
    symmetric range shows asymmetry.
    """
    u = _as_1d("u", u)
    if n_levels < 1:
        raise ValueError("n_levels must be >= 1")
    lo, hi = float(np.nanmin(u)), float(np.nanmax(u))
    if hi <= lo:
        return [(lo, hi, fit_figures(y, yhat))]
    edges = np.linspace(lo, hi, n_levels + 1)
    idx = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, n_levels - 1)
    y = np.asarray(y, float)
    yhat = np.asarray(yhat, float)
    return [(float(edges[i]), float(edges[i + 1]), fit_figures(y[idx == i], yhat[idx == i])) for i in range(n_levels)]


@dataclass(frozen=True)
class Band:
    """Residual content of one frequency band [f_lo, f_hi) Hz (by Parseval on the whole record).

    ``rmse`` is the RMS of the residual's part in the band (m), ``y_rms`` the measured output's (m, mean
    removed); ``fit_percent = 100 (1 − rmse/y_rms)``. The squared band ``rmse`` values add up to the residual's
    mean square (bias included in the first band).
    """

    f_lo: float
    f_hi: float
    rmse: float
    y_rms: float
    fit_percent: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def fit_by_band(y: np.ndarray, yhat: np.ndarray, fs: float, edges: np.ndarray | None = None,
                n_bands: int = 6) -> list[Band]:
    """Residual RMS per frequency band, from one FFT of the whole record.

    Default edges: 0, then ``n_bands − 1`` log-spaced edges from 2/T to fs/2 (T the record length).
    """
    y = _as_1d("y", y)
    e = y - _as_1d("yhat", yhat)
    n = y.size
    if n < 4:
        raise ValueError("need at least 4 samples for a band breakdown")
    if edges is None:
        f_min = 2.0 * fs / n
        edges = np.concatenate(([0.0], np.geomspace(f_min, fs / 2.0, n_bands)))
        edges[-1] = fs / 2.0 + 1e-9 * fs  # include Nyquist
    edges = np.asarray(edges, float)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    w = np.full(f.size, 2.0)  # one-sided spectrum: double all but DC and Nyquist
    w[0] = 1.0
    if n % 2 == 0:
        w[-1] = 1.0
    E = w * np.abs(np.fft.rfft(e)) ** 2 / n ** 2
    Yc = w * np.abs(np.fft.rfft(y - y.mean())) ** 2 / n ** 2
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (f >= lo) & (f < hi)
        r = float(np.sqrt(E[m].sum()))
        yr = float(np.sqrt(Yc[m].sum()))
        out.append(Band(float(lo), float(min(hi, fs / 2.0)), r, yr,
                        100.0 * (1.0 - r / yr) if yr > 0 else float("nan")))
    return out


def harmonics(t: np.ndarray, e: np.ndarray, freq: float, n_harm: int = 10) -> tuple[np.ndarray, float]:
    """Amplitudes of the residual at ``k·freq`` (k = 1..n_harm, least squares) and the share of its variance.

    A residual that repeats with a periodic drive is a loop-shape error, not noise: odd harmonics come from a
    symmetric shape error, even harmonics from an asymmetric one.
    """
    t = _as_1d("t", t)
    e = _as_1d("e", e)
    ec = e - e.mean()
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    ks = [k for k in range(1, n_harm + 1) if k * freq < 0.45 * fs]
    if not ks or ec.size < 4 * len(ks) + 1:
        return np.zeros(0), 0.0
    tt = t - t[0]
    X = np.column_stack([f(2 * np.pi * k * freq * tt) for k in ks for f in (np.cos, np.sin)])
    coef, *_ = np.linalg.lstsq(X, ec, rcond=None)
    amp = np.hypot(coef[0::2], coef[1::2])
    fitted = X @ coef
    var = float(ec @ ec)
    return amp, (float(fitted @ fitted) / var if var > 0 else 0.0)


def ringing(t: np.ndarray, e: np.ndarray, noise: float, window_s: float = 0.05) -> tuple[float, float] | None:
    """Oscillation of the residual right after a step: ``(frequency Hz, RMS m)`` or None.

    The residual's first ``window_s`` seconds, minus a moving average over ~1 ms-scale trends, must carry an
    RMS above 4× the output noise and a spectral peak 5× above the median — a resonance the model lacks.
    """
    t = _as_1d("t", t)
    e = _as_1d("e", e)
    if t.size < 16:
        return None
    dt = float(np.median(np.diff(t)))
    n = int(min(e.size, max(16, round(window_s / dt))))
    x = e[:n]
    k = max(3, n // 16)
    trend = np.convolve(np.pad(x, (k // 2, k - 1 - k // 2), mode="edge"), np.ones(k) / k, mode="valid")
    d = x - trend
    rms = float(np.sqrt(np.mean(d * d)))
    if rms <= 4.0 * noise:
        return None
    spec = np.abs(np.fft.rfft(d * np.hanning(n)))
    f = np.fft.rfftfreq(n, dt)
    if spec.size < 4:
        return None
    i = int(np.argmax(spec[1:])) + 1
    if spec[i] < 5.0 * float(np.median(spec[1:])):
        return None
    return float(f[i]), rms


def spectral_peaks(x: np.ndarray, fs: float, min_ratio: float = 4.0, max_peaks: int = 3,
                   exclude: tuple[float, ...] = ()) -> list[tuple[float, float]]:
    """Peaks of a signal's Welch power spectrum above its local level: ``[(frequency Hz, ratio), ...]``.

    The local level is the median power within ±half an octave (on a log-frequency grid), so broad trends
    (1/f, a low-pass roll-off) are not peaks while a resonance or a vibration line is, even a broad one. The
    ratio is averaged over 5 bins so single noisy bins do not count. Frequencies in ``exclude`` (e.g. harmonics
    of a sine drive, ±2 bins) and the lowest 4 bins are ignored. Strongest first.
    """
    from scipy.signal import find_peaks, welch
    x = _as_1d("x", x)
    n = x.size
    if n < 256:
        return []
    nper = int(min(n, max(256, n // 8)))
    f, P = welch(x - x.mean(), fs, nperseg=nper)
    if f.size < 16 or not np.any(P > 0):
        return []
    lf = np.log10(f[4:])
    lp = np.log10(np.maximum(P[4:], 1e-300))
    grid = np.linspace(lf[0], lf[-1], 400)
    lg = np.interp(grid, lf, lp)
    half = max(1, int(round(np.log10(2 ** 0.5) / (grid[1] - grid[0]))))
    base_g = np.array([np.median(lg[max(0, i - half):i + half + 1]) for i in range(grid.size)])
    ratio = 10 ** (lp - np.interp(lf, grid, base_g))
    ratio = np.convolve(ratio, np.ones(5) / 5, mode="same")
    idx, _ = find_peaks(ratio, height=min_ratio, distance=5)
    fp = f[4:]
    df = f[1] - f[0]
    cand = sorted((i for i in idx if not any(abs(fp[i] - e) <= 2 * df for e in exclude)), key=lambda i: -ratio[i])
    keep: list[int] = []
    for i in cand:  # one resonance gives several local maxima: keep the strongest within ±10 %
        if all(abs(fp[i] - fp[j]) > 0.1 * fp[j] for j in keep):
            keep.append(i)
    return [(float(fp[i]), float(ratio[i])) for i in keep[:max_peaks]]


# ----------------------------------------------------------------------------------------------- everything
@dataclass
class CompareStats:
    """Everything :func:`compare_stats` computes; ``to_dict()`` is the JSON ``hyst compare --json`` prints."""

    fs: float
    noise_sigma: float
    overall: Fit
    segments: list[SegmentFit]
    branches: dict[str, Fit]
    levels: list[tuple[float, float, Fit]]
    bands: list[Band]
    auto: Correlation
    cross: Correlation
    higher: dict[str, Correlation]
    lag_step: int
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self, values: bool = False) -> dict[str, Any]:
        return {
            "fs": self.fs, "n": self.overall.n, "noise_sigma": self.noise_sigma,
            "overall": self.overall.to_dict(),
            "segments": [s.to_dict() for s in self.segments],
            "branches": {k: v.to_dict() for k, v in self.branches.items()},
            "levels": [{"u_lo": lo, "u_hi": hi, **f.to_dict()} for lo, hi, f in self.levels],
            "bands": [b.to_dict() for b in self.bands],
            "whiteness": self.auto.to_dict(values),
            "cross": self.cross.to_dict(values),
            "higher_order": {k: c.to_dict(values) for k, c in self.higher.items()},
            "lag_step": self.lag_step,
            **self.extra,
        }


def compare_stats(t: np.ndarray, u: np.ndarray, y: np.ndarray, yhat: np.ndarray, *, n_levels: int = 5,
                  band_edges: np.ndarray | None = None, max_lag: int = 25, lag_step: int | None = None,
                  conf: float = 0.99, segment_kw: dict[str, Any] | None = None) -> CompareStats:
    """All fit figures and residual tests of a model output ``yhat`` against measured ``y``.

    Parameters
    ----------
    t, u, y, yhat : ndarray
        Sample times (s), input (V), measured and model output (m), equal length, finite.
    n_levels : int
        Input-level bins.
    band_edges : ndarray, optional
        Frequency band edges (Hz); default see :func:`fit_by_band`.
    max_lag : int
        Number of lags of the correlation tests (MATLAB ``resid`` default 25).
    lag_step : int, optional
        Samples per lag; default :func:`auto_lag_step`.
    conf : float
        Confidence of the bounds (0.99 as MATLAB ``resid``).
    segment_kw : dict, optional
        Keyword arguments for :func:`segment_input`.
    """
    t, u, y, yhat = (_as_1d(n, a) for n, a in (("t", t), ("u", u), ("y", y), ("yhat", yhat)))
    n = t.size
    if not (u.size == y.size == yhat.size == n):
        raise ValueError("t, u, y and yhat must have the same length")
    if n < 8:
        raise ValueError(f"need at least 8 samples to compare, got {n}")
    for name, a in (("t", t), ("u", u), ("y", y), ("yhat", yhat)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains non-finite values")
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise ValueError("sample times must increase")
    fs = 1.0 / dt
    e = y - yhat
    step = auto_lag_step(n, max_lag, fs, u) if lag_step is None else int(lag_step)
    branches = fit_by_branch(u, y, yhat)
    return CompareStats(
        fs=fs, noise_sigma=noise_sigma(y), overall=fit_figures(y, yhat),
        segments=fit_by_segment(t, u, y, yhat, **(segment_kw or {})),
        branches=branches, levels=fit_by_level(u, y, yhat, n_levels),
        bands=fit_by_band(y, yhat, fs, band_edges),
        auto=autocorr(e, max_lag, step, conf, dt), cross=crosscorr(e, u, max_lag, step, conf, dt),
        higher=higher_order_tests(e, u, max_lag, step, conf, dt), lag_step=step,
        extra={"loop_orientation": loop_orientation(u, y), "harmonics": _harmonic_summary(t, u, e),
               "ringing": _ringing_summary(t, u, e, noise_sigma(y)), "peaks": _peak_summary(t, u, e, fs)})


def _peak_summary(t: np.ndarray, u: np.ndarray, e: np.ndarray, fs: float) -> list[dict[str, float]]:
    drives = [s.freq for s in segment_input(t, u) if s.kind == "sine"]
    exclude = tuple(k * f for f in drives for k in range(1, 41))
    return [{"freq": f, "ratio": r} for f, r in spectral_peaks(e, fs, exclude=exclude)]


def _harmonic_summary(t: np.ndarray, u: np.ndarray, e: np.ndarray) -> dict[str, Any] | None:
    segs = [s for s in segment_input(t, u) if s.kind == "sine"]
    if not segs:
        return None
    s = max(segs, key=lambda s: s.stop - s.start)
    amp, share = harmonics(t[s.start:s.stop], e[s.start:s.stop], s.freq)
    if amp.size == 0:
        return None
    return {"freq": s.freq, "t0": float(t[s.start]), "t1": float(t[s.stop - 1]), "amplitudes": amp.tolist(),
            "share": share}


def _ringing_summary(t: np.ndarray, u: np.ndarray, e: np.ndarray, noise: float) -> list[dict[str, float]]:
    out = []
    for s in segment_input(t, u):
        if s.kind != "step":
            continue
        r = ringing(t[s.start:], e[s.start:], noise)
        if r is not None:
            out.append({"t": float(t[s.start]), "freq": r[0], "rms": r[1]})
    return out


def loop_orientation(u: np.ndarray, y: np.ndarray, n_levels: int = 8) -> int:
    """+1 when the falling branch lies above the rising one (counter-clockwise loop, as a piezo stage), −1 for
    the opposite, 0 when undecided; compared level bin by level bin so the input's distribution does not matter.
    """
    u = _as_1d("u", u)
    y = _as_1d("y", y)
    du = np.diff(u, prepend=u[:1])
    if u.size < 4 or np.ptp(u) <= 0:
        return 0
    edges = np.linspace(u.min(), u.max(), n_levels + 1)
    idx = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, n_levels - 1)
    diffs = []
    for i in range(n_levels):
        r = (idx == i) & (du > 0)
        f = (idx == i) & (du < 0)
        if r.sum() >= 3 and f.sum() >= 3:
            diffs.append(np.mean(y[f]) - np.mean(y[r]))
    if not diffs:
        return 0
    m = float(np.median(diffs))
    return int(np.sign(m))
