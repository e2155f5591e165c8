"""A record shifted in time by linear interpolation: ``np.interp(t - tau, t, v)`` in one compiled pass.

The delay effect evaluates this thousands of times per diagnosis (every simulation, and every Jacobian column it
carries on the output side). ``np.interp`` binary-searches each query; here the query ``t - tau`` is ordered as
``t`` is, so the bracketing sample is found by walking forward from the last one (O(n) in all). The arithmetic is
``np.interp``'s own — the slope ``(v[j+1] − v[j]) / (t[j+1] − t[j])`` times the distance from ``t[j]``, the exact
sample value where the query hits a sample or the last sample, and its fallbacks for non-finite values — so
the results are bit for bit those of ``np.interp`` (tested), and no diagnosis changes with it.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["shift", "shift_columns"]


@njit(cache=True, nogil=True)
def _bracket(t: np.ndarray, xv: float, j: int) -> int:
    """The largest ``j`` with ``t[j] <= xv`` (``t`` non-decreasing, ``t[0] <= xv <= t[-1]``), from a guess."""
    n = t.shape[0]
    while j > 0 and t[j] > xv:
        j -= 1
    while j < n - 1 and t[j + 1] <= xv:
        j += 1
    return j


@njit(cache=True, nogil=True)
def _shift(t: np.ndarray, tau: float, v: np.ndarray, left: float, right: float) -> np.ndarray:
    n = t.shape[0]
    out = np.empty(n)
    j = 0
    for i in range(n):
        xv = t[i] - tau
        if xv != xv:
            out[i] = xv
            continue
        if xv < t[0]:
            out[i] = left
            continue
        if xv > t[n - 1]:
            out[i] = right
            continue
        j = _bracket(t, xv, j)
        if j == n - 1 or t[j] == xv:
            out[i] = v[j]
            continue
        slope = (v[j + 1] - v[j]) / (t[j + 1] - t[j])
        r = slope * (xv - t[j]) + v[j]
        if r != r:  # np.interp's fallbacks: from the other end, then the common value
            r = slope * (xv - t[j + 1]) + v[j + 1]
            if r != r and v[j] == v[j + 1]:
                r = v[j]
        out[i] = r
    return out


@njit(cache=True, nogil=True)
def _shift_columns(t: np.ndarray, tau: float, V: np.ndarray) -> np.ndarray:
    n, k = V.shape
    out = np.empty((n, k))
    j = 0
    for i in range(n):
        xv = t[i] - tau
        if xv != xv:
            out[i, :] = xv
            continue
        if xv < t[0]:
            out[i, :] = V[0, :]
            continue
        if xv > t[n - 1]:
            out[i, :] = V[n - 1, :]
            continue
        j = _bracket(t, xv, j)
        if j == n - 1 or t[j] == xv:
            out[i, :] = V[j, :]
            continue
        dt = t[j + 1] - t[j]
        dx = xv - t[j]
        dx1 = xv - t[j + 1]
        for c in range(k):
            slope = (V[j + 1, c] - V[j, c]) / dt
            r = slope * dx + V[j, c]
            if r != r:
                r = slope * dx1 + V[j + 1, c]
                if r != r and V[j, c] == V[j + 1, c]:
                    r = V[j, c]
            out[i, c] = r
    return out


def shift(t: np.ndarray, tau: float, v: np.ndarray, *, left: float | None = None,
          right: float | None = None) -> np.ndarray:
    """``np.interp(t - tau, t, v, left, right)`` (``t`` non-decreasing; ``left``/``right`` default to the end
    values, as ``np.interp``'s do). ``tau`` > 0 delays ``v``, ``tau`` < 0 advances it."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError(f"shift needs t and v of one shape (1-D), not {t.shape} and {v.shape}")
    if t.size == 0:
        return v.copy()
    return _shift(t, float(tau), v, float(v[0] if left is None else left), float(v[-1] if right is None else right))


def shift_columns(t: np.ndarray, tau: float, V: np.ndarray) -> np.ndarray:
    """:func:`shift` of every column of ``V`` (n, k), the end values held: one pass for a Jacobian's columns."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    V = np.ascontiguousarray(V, dtype=np.float64)
    if V.ndim != 2 or V.shape[0] != t.size or t.ndim != 1:
        raise ValueError(f"shift_columns needs V of shape (len(t), k), not {V.shape} for {t.shape}")
    if t.size == 0:
        return V.copy()
    return _shift_columns(t, float(tau), V)
