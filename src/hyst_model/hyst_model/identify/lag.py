"""The input-to-output lag of an MBW stage from equation-error fits of the record shifted against itself.

A transport delay of d samples makes (3.21) wrong at every step, whatever its parameters; with the output advanced by
d samples the record is an MBW record again and its equation-error start
(:func:`~hyst_model.identify.equation_error.equation_error_starts`) reaches the noise floor in free run. The free-run
error of the best start over the lag is therefore sharp and single-dipped where the stage is an MBW: on a generated
wide-shape piezo stage with a 13.5-sample sensor delay it fell from 41x the noise floor at lag 0 to 1.05x at lag 13
and rose again to 125x at lag 40, while the impulse response of Δy to Δu (:func:`hyst_model.effects.delay._fir_delay`)
was smeared by the stage's own memory and peaked at its last tap.
"""
from __future__ import annotations

import numpy as np

from ..model import MBWModel
from .memo import FitMemo, content_key

__all__ = ["equation_error_lag"]

#: Profiles already computed, by record content (a diagnosis starts the delay a dozen times on one record).
_MEMO = FitMemo(8)


def _cost(u: np.ndarray, y: np.ndarray, d: int, rows: int) -> float:
    from ..models import data_config  # late: the model registry imports this package's users
    from .equation_error import equation_error_starts
    n = u.size
    us, ys = u[: n - d], y[d:]
    cfg = data_config(us, ys)
    base = MBWModel(cfg["u_scale"], cfg["y_scale"], rate=True, offset_bound=cfg["offset_bound"])
    with np.errstate(all="ignore"):
        _, costs = equation_error_starts(base, us, ys, max_rows=rows)
    return float(costs[0]) if costs.size and np.isfinite(costs[0]) else np.inf


def _busiest_window(u: np.ndarray, length: int) -> slice:
    """The ``length`` consecutive samples over which the input changes most (sum of |Δu|)."""
    if u.size <= length:
        return slice(0, u.size)
    c = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(u)))])
    k = int(np.argmax(c[length - 1:] - c[: c.size - length + 1]))
    return slice(k, k + length)


def equation_error_lag(u: np.ndarray, y: np.ndarray, max_lag: int, rows: int = 2000,
                       max_samples: int = 20000) -> tuple[float, np.ndarray]:
    """Lag (samples, fractional) at which the MBW equation-error start of (u_k, y_{k+d}) fits best in free run.

    Lags 0, 4, 8, … ``max_lag`` first, then every lag within 3 of the best of those, then a parabola through the
    best and its neighbours (clipped to half a sample). A delay is the same throughout a record, so longer records
    are searched on the ``max_samples`` samples where the input changes most: the free runs of a 60k-sample
    record then cost what a 20k one's do.

    Parameters
    ----------
    u, y : ndarray
        Input (V) and output (m) of one record.
    max_lag : int
        Largest lag tried (samples).
    rows : int
        Equation rows per regression (a strided subset on longer records).
    max_samples : int
        Longest stretch of the record searched.

    Returns
    -------
    lag : float
        The best lag (samples); 0.0 where nothing is finite.
    profile : ndarray, shape (max_lag + 1,)
        Free-run RMSE (m) of the best start per lag; NaN where not evaluated.
    """
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    w = _busiest_window(u, int(max_samples))
    u, y = u[w], y[w]
    max_lag = int(max(0, min(max_lag, u.size // 4)))
    lag, prof = _MEMO.get_or(content_key("lag", u, y, max_lag, rows), lambda: _lag_profile(u, y, max_lag, rows))
    return float(lag), prof


def _lag_profile(u: np.ndarray, y: np.ndarray, max_lag: int, rows: int) -> tuple[float, np.ndarray]:
    """The search of :func:`equation_error_lag` on the chosen window: coarse grid, refined about its best, parabola."""
    prof = np.full(max_lag + 1, np.nan)

    def at(d: int) -> float:
        if np.isnan(prof[d]):
            prof[d] = _cost(u, y, d, rows)
        return float(prof[d])

    for d in sorted(set(range(0, max_lag + 1, 4)) | {max_lag}):
        at(d)
    best = int(np.nanargmin(np.where(np.isfinite(prof), prof, np.nan))) if np.isfinite(prof).any() else 0
    for d in range(max(best - 3, 0), min(best + 3, max_lag) + 1):
        at(d)
    fin = np.where(np.isfinite(prof), prof, np.nan)
    if not np.isfinite(fin).any():
        lag = 0.0
    else:
        k = int(np.nanargmin(fin))
        lag = float(k)
        if 0 < k < max_lag and np.isfinite(fin[k - 1]) and np.isfinite(fin[k + 1]):
            den = fin[k - 1] - 2.0 * fin[k] + fin[k + 1]
            if den > 0:
                lag = k + float(np.clip(0.5 * (fin[k - 1] - fin[k + 1]) / den, -0.5, 0.5))
    return lag, prof
