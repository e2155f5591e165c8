"""Small residual-analysis helpers shared by the effects' signatures and the diagnose engine (numpy only)."""
from __future__ import annotations

import numpy as np

from .quantised import quantised_floor

__all__ = ["sample_time", "holds", "noise_floor", "record_floor", "record_floor_step", "smooth", "rate_of", "midrange",
           "corr", "fmt_len"]


_LAST_T: list = [None]  # one (time vector, its fingerprint, period) tuple; the vector kept alive keeps its id


def sample_time(t: np.ndarray) -> float:
    """Median sample period (s) of a time vector.

    A fit asks this of the same 10⁴–10⁵-sample record thousands of times (every effect, every simulation), so
    the answer for the last vector is kept while it is the same, unchanged object (one tuple: read whole).
    """
    t = np.asarray(t, dtype=np.float64)
    if t.size <= 1:
        return 1e-3
    key = (t.size, float(t[0]), float(t[t.size // 2]), float(t[-1]))
    snap = _LAST_T[0]
    if snap is not None and snap[0] is t and snap[1] == key:
        return float(snap[2])
    dt = float(np.median(np.diff(t)))
    _LAST_T[0] = (t, key, dt)
    return dt


def holds(u: np.ndarray, dt: float, min_seconds: float = 0.3, rel_tol: float = 2e-3) -> list[tuple[int, int, float]]:
    """Stretches where the input is held constant.

    Returns
    -------
    list of (start, stop, step)
        Index range of each hold of at least ``min_seconds`` and the input step (V) that led into it
        (``u[start] - u[start-1]`` measured over the preceding hold's level; 0 for the first hold).
    """
    u = np.asarray(u, dtype=np.float64)
    span = float(np.ptp(u)) if u.size else 0.0
    if span <= 0:
        return [(0, u.size, 0.0)] if u.size * dt >= min_seconds else []
    tol = rel_tol * span
    moving = np.abs(np.diff(u)) > tol
    edges = np.flatnonzero(moving) + 1
    bounds = np.concatenate([[0], edges, [u.size]])
    out: list[tuple[int, int, float]] = []
    prev_level = None
    for a, b in zip(bounds[:-1], bounds[1:]):
        if (b - a) * dt >= min_seconds:
            level = float(u[a])
            step = 0.0 if prev_level is None and a == 0 else level - float(u[max(a - 1, 0)]) \
                if prev_level is None else level - prev_level
            out.append((int(a), int(b), float(step)))
            prev_level = level
    return out


def noise_floor(y: np.ndarray) -> float:
    """Robust white-noise level (same unit as y) from second differences: var(Δ²e) = 6σ² for white e.

    Smooth signal content sampled fast contributes little to Δ², and the median absolute deviation ignores
    the few samples at steps. Quantisation error is white only where the noise dithers it (a white part of at
    least half the step); a reading quantised more coarsely is read by :func:`record_floor` through
    :func:`.quantised.quantised_floor` instead.
    """
    y = np.asarray(y, dtype=np.float64)
    if y.size < 5:
        return 0.0
    d2 = np.diff(y, 2)
    mad = np.median(np.abs(d2 - np.median(d2)))
    sigma = 1.4826 * mad / np.sqrt(6.0)
    if sigma == 0.0:  # coarse quantisation: most Δ² are exactly 0; fall back to the RMS
        sigma = float(np.sqrt(np.mean(d2 ** 2) / 6.0))
    return float(sigma)


def record_floor(y: np.ndarray, e: np.ndarray, step: float | None = None) -> float:
    """The white-noise floor of a record ``y`` given a model's residual ``e`` on it (m): the smaller of the two
    :func:`noise_floor` values (the residual's where it is positive).

    The second differences of y carry signal wherever the record moves fast (sweeps, sines near 100 Hz: the
    noise came out 1.6x too high on generated sweeps, 9x on one sine record), which hides small effects "at the
    noise floor"; the model's residual has that signal removed. Neither can underestimate white sensor noise, so
    the smaller is kept (``hyst diagnose`` with the base's residual, ``hyst fit`` with its fit's). A reading on a
    lattice coarser than its white noise has the floor of :func:`.quantised.quantised_floor` instead (``step``:
    that lattice's, when known from the record as read and ``y`` is the record with lines taken out).
    """
    return record_floor_step(y, e, step)[0]


def record_floor_step(y: np.ndarray, e: np.ndarray, step: float | None = None) -> tuple[float, float]:
    """:func:`record_floor` and the lattice step it was read on (0.0 where second differences read it)."""
    coarse, q = quantised_floor(y, e, step)
    if q > 0.0:
        return coarse, q
    floor_y, floor_e = noise_floor(y), noise_floor(e)
    return (min(floor_y, floor_e) if floor_e > 0 else floor_y), 0.0


def smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (edges padded with the end values)."""
    x = np.asarray(x, dtype=np.float64)
    n = int(max(1, n))
    if n == 1 or x.size < n:
        return x.copy()
    pad = np.concatenate([np.full(n // 2, x[0]), x, np.full(n - 1 - n // 2, x[-1])])
    c = np.cumsum(np.concatenate([[0.0], pad]))
    return (c[n:] - c[:-n]) / n


def rate_of(x: np.ndarray, dt: float, smooth_seconds: float = 0.0) -> np.ndarray:
    """Time derivative (unit/s), optionally of a smoothed copy."""
    xs = smooth(x, int(round(smooth_seconds / dt))) if smooth_seconds > 0 else np.asarray(x, dtype=np.float64)
    return np.gradient(xs, dt)


def midrange(x) -> float:
    """The middle of the range of ``x``: (min + max) / 2 — where the even-order effects centre their terms."""
    x = np.asarray(x, dtype=np.float64)
    return 0.5 * (float(np.min(x)) + float(np.max(x)))


def corr(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation (0 when either side is constant)."""
    a = np.asarray(a, dtype=np.float64) - np.mean(a)
    b = np.asarray(b, dtype=np.float64) - np.mean(b)
    den = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return float(np.dot(a, b) / den) if den > 0 else 0.0


def fmt_len(x_m: float) -> str:
    """A length for people: nm or µm."""
    ax = abs(x_m)
    if ax < 1e-6:
        return f"{x_m * 1e9:.3g} nm"
    if ax < 1e-3:
        return f"{x_m * 1e6:.3g} µm"
    return f"{x_m * 1e3:.3g} mm"
