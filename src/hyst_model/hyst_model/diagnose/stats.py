"""Fit figures and residual tests for comparing a model with measurements (pure numpy/scipy).

Everything ``hyst compare`` and ``hyst diagnose`` say about *where* a model fails comes from here (the fit
figures live in :mod:`.figures`, the correlation tests in :mod:`.correlation`, the input segmentation in
:mod:`.segments` and the residual's harmonics, ringing and peaks in :mod:`.spectra`; all are re-exported here):

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
from ..effects.quantised import lattice_step, quantised_floor
from ..effects.signals import record_floor_step
from .figures import Fit, _as_1d, fit_figures, noise_sigma
from .floor import read_floor
from .lines import disturbance_lines, without_lines
from .segments import Segment, SegmentFit, fit_by_segment, segment_input
from .spectra import harmonics, ringing, spectral_peaks

__all__ = [
    "Fit", "Segment", "SegmentFit", "Band", "Correlation", "CompareStats",
    "fit_figures", "noise_sigma", "segment_input", "fit_by_segment", "fit_by_branch", "fit_by_level",
    "fit_by_band", "loop_orientation", "harmonics", "ringing", "spectral_peaks", "autocorr", "crosscorr",
    "higher_order_tests", "auto_lag_step", "compare_stats", "z_value",
]


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
    sigma = noise_sigma(y)
    lattice = lattice_step(y)
    coarse, q = quantised_floor(y, e, lattice)
    if q > 0.0:   # a reading in steps not fine against its noise: differences misread it (effects.quantised)
        sigma = coarse
    lines = disturbance_lines(t, u, e, sigma)
    yc, ec = y, e
    if lines and lattice > 0.0:   # local fits read much of a line: the floor of the reading without them
        yc, ec = without_lines(t, y, lines), without_lines(t, e, lines)
    white, q = record_floor_step(yc, ec, lattice)   # as hyst diagnose judges it
    if q > 0.0:
        sigma = white
    return CompareStats(
        fs=fs, noise_sigma=sigma, overall=fit_figures(y, yhat),
        segments=fit_by_segment(t, u, y, yhat, **(segment_kw or {})),
        branches=branches, levels=fit_by_level(u, y, yhat, n_levels),
        bands=fit_by_band(y, yhat, fs, band_edges),
        auto=autocorr(e, max_lag, step, conf, dt), cross=crosscorr(e, u, max_lag, step, conf, dt),
        higher=higher_order_tests(e, u, max_lag, step, conf, dt), lag_step=step,
        extra={"loop_orientation": loop_orientation(u, y), "harmonics": _harmonic_summary(t, u, e),
               "ringing": _ringing_summary(t, u, e, sigma), "peaks": _peak_summary(t, u, e, fs),
               "disturbances": [ln.to_json() for ln in lines], **_held(t, u, y, white, q, lines)})


def _held(t: np.ndarray, u: np.ndarray, y: np.ndarray, white: float, step: float,
          lines: list) -> dict[str, float | None]:
    """``noise_holds``: the output noise read in the record's holds without the residual's lines (:mod:`.colour`),
    where it exceeds the white part ``white`` (as ``hyst diagnose`` judges it: ``record_floor_step``, read on the
    lattice ``step`` if any) by the margin — noise that is not white —, else None."""
    floor, _ = read_floor(t, u, y, white, lines=lines, step=step)   # it reads the holds without the lines
    return {"noise_holds": floor.held.rms if floor.held is not None else None, "noise_white": white,
            "noise_step": step if step > 0.0 else None}


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
