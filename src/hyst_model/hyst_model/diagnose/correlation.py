"""Residual whiteness, residual–input cross-correlation and higher-order correlation tests, with confidence
bounds (pure numpy/scipy); definitions and references in :mod:`hyst_model.diagnose.stats`, which re-exports these.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as _sps

from .figures import _as_1d

__all__ = ["Correlation", "autocorr", "crosscorr", "higher_order_tests", "auto_lag_step", "z_value"]


def z_value(conf: float) -> float:
    """Two-sided standard-normal quantile for confidence ``conf`` (2.576 for 0.99)."""
    if not 0.0 < conf < 1.0:
        raise ValueError("conf must be in (0, 1)")
    return float(_sps.norm.ppf(0.5 + conf / 2.0))


@dataclass(frozen=True)
class Correlation:
    """A normalised correlation function with its confidence bound.

    Attributes
    ----------
    name : str
        ``"auto"`` (residual whiteness), ``"cross"`` (residual vs input) or a higher-order test name.
    lags : ndarray of int
        Lags in samples (already multiplied by ``lag_step``).
    values : ndarray
        Normalised correlation at each lag, in [−1, 1].
    bound : float
        Two-sided confidence bound: values outside ±bound are significant.
    dt : float
        Sample period (s), so ``lags * dt`` are lags in seconds.
    """

    name: str
    lags: np.ndarray
    values: np.ndarray
    bound: float
    dt: float = 1.0

    @property
    def _test(self) -> np.ndarray:
        # The autocorrelation is 1 at lag 0 by definition: leave it out of the test.
        return self.lags != 0 if self.name == "auto" else np.ones(self.lags.size, bool)

    @property
    def max_abs(self) -> float:
        """Largest |value| over the tested lags."""
        v = np.abs(self.values[self._test])
        return float(v.max()) if v.size else 0.0

    @property
    def lag_at_max(self) -> int:
        m = self._test
        return int(self.lags[m][np.argmax(np.abs(self.values[m]))]) if m.any() else 0

    @property
    def frac_outside(self) -> float:
        """Fraction of tested lags outside the bound (≈ 1 − conf for a model that is right)."""
        m = self._test
        return float(np.mean(np.abs(self.values[m]) > self.bound)) if m.any() else 0.0

    @property
    def significant(self) -> bool:
        """True when the correlation is clearly outside the bound, beyond what chance gives over many lags.

        One lag past 1.5× the bound (about 3.9 σ at 99 %: under 1 % false alarms over 51 white lags) or more
        than 10 % of the lags outside it.
        """
        return bool(self.max_abs > 1.5 * self.bound or self.frac_outside > 0.1)

    def to_dict(self, values: bool = False) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "bound": float(self.bound), "max_abs": self.max_abs,
                             "lag_at_max_s": self.lag_at_max * self.dt, "frac_outside": self.frac_outside,
                             "significant": self.significant}
        if values:
            d["lags_s"] = (self.lags * self.dt).tolist()
            d["values"] = self.values.tolist()
        return d


def _centred(x: np.ndarray) -> np.ndarray:
    x = _as_1d("x", x)
    return x - x.mean()


def _xcorr_full(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unnormalised Σ_k a_k b_{k−τ} for τ = −(n−1)..(n−1) (FFT), index n−1 is τ = 0."""
    n = a.size
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    r = np.fft.irfft(np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft)), nfft)
    return np.concatenate((r[nfft - (n - 1):], r[:n]))


def _norm_xcorr(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    a = _centred(a)
    b = _centred(b)
    den = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    if den == 0.0:
        return np.zeros(lags.size)
    full = _xcorr_full(a, b)
    return full[a.size - 1 + lags] / den


def _lags(max_lag: int, lag_step: int, n: int, two_sided: bool) -> np.ndarray:
    if max_lag < 1 or lag_step < 1:
        raise ValueError("max_lag and lag_step must be >= 1")
    k = np.arange(0, max_lag + 1) * lag_step
    k = k[k < n]
    return np.concatenate((-k[:0:-1], k)) if two_sided else k


def autocorr(e: np.ndarray, max_lag: int = 25, lag_step: int = 1, conf: float = 0.99,
             dt: float = 1.0) -> Correlation:
    """Residual whiteness test: normalised autocorrelation at lags 0..max_lag·lag_step, bound z/√N."""
    e = _as_1d("e", e)
    lags = _lags(max_lag, lag_step, e.size, two_sided=False)
    return Correlation("auto", lags, _norm_xcorr(e, e, lags), z_value(conf) / np.sqrt(e.size), dt)


def crosscorr(e: np.ndarray, u: np.ndarray, max_lag: int = 25, lag_step: int = 1, conf: float = 0.99,
              dt: float = 1.0, name: str = "cross") -> Correlation:
    """Residual–input independence test: r_εu(τ) for τ = −L..L, bound z·sqrt(P/N) (Ljung §16.6).

    ``P = Σ_{|k|≤L} w_k r_ε(k) r_u(k)`` with Bartlett weights ``w_k = 1 − |k|/(L+1)`` over the same (stepped)
    lags. Significant values at τ > 0 (past inputs) mean input-driven behaviour the model lacks; at τ < 0
    (future inputs) they indicate feedback in the data (closed loop).
    """
    e = _as_1d("e", e)
    u = _as_1d("u", u)
    if e.size != u.size:
        raise ValueError("e and u differ in length")
    lags = _lags(max_lag, lag_step, e.size, two_sided=True)
    r = _norm_xcorr(e, u, lags)
    re = _norm_xcorr(e, e, lags)
    ru = _norm_xcorr(u, u, lags)
    w = 1.0 - np.abs(lags) / (lags.max() + lag_step)
    p = max(float(np.sum(w * re * ru)), 1.0 if not np.any(ru) else 0.0)
    p = max(p, 1e-12)
    return Correlation(name, lags, r, z_value(conf) * np.sqrt(p / e.size), dt)


def higher_order_tests(e: np.ndarray, u: np.ndarray, max_lag: int = 25, lag_step: int = 1, conf: float = 0.99,
                       dt: float = 1.0) -> dict[str, Correlation]:
    """Billings–Voon style higher-order correlation tests (means removed, bound z/√N).

    ``e2_u``   corr(ε², u): residual *size* follows the input level — asymmetry, level-dependent gain;
    ``e_u2``   corr(ε, u²): an even (quadratic) input term the model lacks — asymmetry, saturation;
    ``e_absdu`` corr(ε, |du|): error grows with input speed, regardless of direction — rate dependence, dynamics;
    ``e2_u2``  corr(ε², u²): residual size follows the input magnitude — saturation, missing nonlinear gain.

    A linear-in-the-input model error shows in the ordinary cross-correlation; these catch the even-order
    terms it is blind to (Billings & Voon, Int. J. Control 44(1), 1986).
    """
    e = _as_1d("e", e)
    u = _as_1d("u", u)
    ec = _centred(e)
    uc = _centred(u)
    absdu = np.abs(np.diff(u, prepend=u[:1]))
    lags = _lags(max_lag, lag_step, e.size, two_sided=True)
    bound = z_value(conf) / np.sqrt(e.size)
    pairs = {"e2_u": (ec * ec, uc), "e_u2": (ec, uc * uc), "e_absdu": (ec, absdu), "e2_u2": (ec * ec, uc * uc)}
    return {k: Correlation(k, lags, _norm_xcorr(a, b, lags), bound, dt) for k, (a, b) in pairs.items()}


def auto_lag_step(n: int, max_lag: int = 25, fs: float = 1.0, u: np.ndarray | None = None) -> int:
    """Lag spacing so ``max_lag`` lags look far enough back on oversampled records.

    The lags should span about a quarter of the input's dominant period (where a loop's memory shows) but
    never more than a tenth of the record; without an input it spans 1/50 of the record. 1 for short records.
    """
    span = n / 50.0
    if u is not None and u.size == n and n >= 16:
        uc = _centred(np.asarray(u, float))
        spec = np.abs(np.fft.rfft(uc))
        spec[0] = 0.0
        k = int(np.argmax(spec))
        if k > 0 and spec[k] > 0:
            span = min(n / (4.0 * k), n / 10.0)
    return max(1, int(span // max_lag))
