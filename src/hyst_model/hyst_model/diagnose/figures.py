"""Fit figures (RMSE, NRMSE, fit %, bias, max error) and the sensor-noise estimate (pure numpy); definitions in
:mod:`hyst_model.diagnose.stats`, which re-exports these.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["Fit", "fit_figures", "noise_sigma"]


@dataclass(frozen=True)
class Fit:
    """Fit figures of one stretch of data.

    Attributes
    ----------
    n : int
        Number of samples.
    rmse : float
        Root-mean-square residual, in the unit of y (m).
    nrmse : float
        ``rmse / (max(y) − min(y))``; NaN when y is constant.
    fit_percent : float
        ``100 (1 − ‖ε‖/‖y − ȳ‖)`` (MATLAB ``compare``); NaN when y is constant.
    bias : float
        Mean residual (m): a pure offset error shows here.
    max_abs : float
        Largest absolute residual (m).
    """

    n: int
    rmse: float
    nrmse: float
    fit_percent: float
    bias: float
    max_abs: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def _as_1d(name: str, a: Any) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def fit_figures(y: np.ndarray, yhat: np.ndarray) -> Fit:
    """RMSE, NRMSE, fit %, bias and max error of ``yhat`` against measured ``y``.

    Non-finite samples of either signal are ignored. An empty selection gives ``n = 0`` and NaN figures.
    """
    y = _as_1d("y", y)
    yhat = _as_1d("yhat", yhat)
    if y.shape != yhat.shape:
        raise ValueError(f"y and yhat differ in length ({y.size} vs {yhat.size})")
    ok = np.isfinite(y) & np.isfinite(yhat)
    y, yhat = y[ok], yhat[ok]
    n = int(y.size)
    if n == 0:
        nan = float("nan")
        return Fit(0, nan, nan, nan, nan, nan)
    e = y - yhat
    rmse = float(np.sqrt(np.mean(e * e)))
    span = float(np.max(y) - np.min(y))
    dev = float(np.linalg.norm(y - y.mean()))
    nrmse = rmse / span if span > 0 else float("nan")
    fit = 100.0 * (1.0 - float(np.linalg.norm(e)) / dev) if dev > 0 else float("nan")
    return Fit(n, rmse, nrmse, fit, float(e.mean()), float(np.max(np.abs(e))))


def noise_sigma(x: np.ndarray) -> float:
    """Robust estimate of white measurement noise on a smooth signal (same unit as ``x``).

    Uses the median absolute third difference: smooth motion (sines, ramps) nearly cancels there while white
    noise of standard deviation σ has std σ·sqrt(20). Steps only affect a few samples, which the median ignores.
    """
    x = _as_1d("x", x)
    x = x[np.isfinite(x)]
    if x.size < 8:
        return 0.0
    d3 = np.diff(x, 3)
    return float(1.4826 * np.median(np.abs(d3 - np.median(d3))) / np.sqrt(20.0))
