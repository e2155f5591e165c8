"""Periodic and oscillatory structure in a residual: harmonics of a periodic drive (:func:`harmonics`), ringing
after steps (:func:`ringing`) and peaks above the residual spectrum's trend (:func:`spectral_peaks`). Pure numpy;
part of :mod:`.stats`, which re-exports everything here.
"""
from __future__ import annotations

import numpy as np

from .figures import _as_1d

__all__ = ["harmonics", "ringing", "spectral_peaks"]


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
