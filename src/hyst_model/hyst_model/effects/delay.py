"""Delay: a transport delay between the applied input and the measured output.

Amplifier filters, sensor electronics and sample-and-hold stages delay the measurement by a fraction of a
millisecond to a few milliseconds. A hysteresis model without it leads the measurement, so its residual is
proportional to minus the output's rate: ε(t) ≈ −τ·ẏ(t). The effect shifts the input by τ seconds
(fractional samples by linear interpolation; before the record starts the input is held at u[0]).
"""
from __future__ import annotations

import numpy as np

from ..errors import EffectError
from ..identify.memo import FitMemo, content_key
from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .shift import shift, shift_columns
from .signals import corr, rate_of

__all__ = ["Delay", "DelayPredictor"]


SIDES = ("input", "output")
#: Condition number of the normalised FIR regression above which :func:`_fir_delay` adds :data:`FIR_RIDGE`.
FIR_COND_MAX = 1e4
#: Ridge of the ill-conditioned FIR regression (the normalised Gram has a unit diagonal).
FIR_RIDGE = 1e-2
#: Impulse-response delays already found, by record content (:func:`_fir_delay_memo`).
_FIR_MEMO = FitMemo(8)


class Delay(Effect):
    """Transport delay τ (s), fractional samples by linear interpolation, on the input or the output side.

    ``delay.side`` (configuration, default ``input``): ``input`` delays the voltage before the hysteresis
    (amplifier, driver filters); ``output`` delays the measured displacement (sensor electronics, sample-and-
    hold). They differ where the input jumps (steps): the hysteresis responds in the same sample, so an
    interpolated input step is not an interpolated output step. ``hyst diagnose`` tries both
    (:meth:`variants`) and keeps whichever validates better; ``hyst fit --effects delay --config
    delay.side=output`` picks one.
    """

    name = "delay"
    summary = "input-to-output transport delay (amplifier and sensor electronics)"
    physics = ("The measurement lags the model by a fixed time: the error is largest where the output moves "
               "fastest and has the opposite sign of the output's rate.")
    kind = "input"

    def __init__(self, config=None):
        super().__init__(config)
        side = str(self._config.get("delay.side", "input"))
        if side not in SIDES:
            raise EffectError(f"delay.side must be one of {', '.join(SIDES)}, not {side!r}")
        self.side = side
        self.kind = side  # instance attribute: where this delay acts
        self.linear = True   # a shift in time, input or output side
        self.on_base = True  # its Smith predictor runs the base model

    @staticmethod
    def variants() -> list[dict[str, str]]:
        """Configurations ``hyst diagnose`` tries, keeping whichever validates better: both sides."""
        return [{"delay.side": s} for s in SIDES]

    def config(self) -> dict[str, float | str]:
        return {"side": self.side}

    def screen_with_refit(self) -> bool:
        return True  # a base fitted without the delay imitates it with its δ terms (both sides)

    def params(self):
        return (Param("tau", 0.0, 0.0, max(0.05, 50 * self.dt), "s", "transport delay from input to output"),)

    def input(self, theta, t, u):
        tau = float(theta[0])
        if tau <= 0.0:
            return u
        return shift(t, tau, u)

    def output(self, theta, t, u, y):
        tau = float(theta[0])
        if tau <= 0.0:
            return y
        return shift(t, tau, y)

    def push(self, theta, t, u, x, y, J):
        """Columns ``J`` of d x / d p delayed as the output is (the operator is linear): d y / d p."""
        tau = float(theta[0])
        return J if tau <= 0.0 else shift_columns(t, tau, J)

    def undo_output(self, theta, t, u, y):
        """Output side: the record advanced by τ (its last value held), the displacement before the delay."""
        tau = float(theta[0])
        if self.side != "output":
            return None
        if tau <= 0.0:
            return y
        return shift(t, -tau, y)

    def online(self, theta, base=None):
        tau = float(theta[0])
        if tau <= 0.0:
            return OnlineEffect()
        if base is None:
            return None
        return DelayPredictor(tau, self.dt, self.side, base)

    def start(self, t, u, y, residual):
        """τ from the data's own impulse response, else from equation-error fits of the record shifted against
        itself.

        The base recursion (3.21) responds to an input change in the same sample (its ζ1·ν_k term), so the
        least-squares FIR response of the output increments to the input increments peaks at lag 0 without a
        delay and at lag τ/Δt with one (split between two lags for fractional delays, as the linear
        interpolation does). A base fitted without the delay imitates it with its δ terms, which hides the
        delay from its residual; the impulse response does not depend on that fit (regularised where the input
        is band-limited, :func:`_fir_delay`). Where it shows no clear peak (a stage with long memory smears it),
        the lag at which an MBW equation-error start fits the shifted record best is used
        (:func:`hyst_model.identify.lag.equation_error_lag`), which needs no base fit either.
        """
        from ..identify.lag import equation_error_lag  # late: identification fits the models effects extend
        t = np.asarray(t, float)
        u = np.asarray(u, float)
        y = np.asarray(y, float)
        dt = float(np.median(np.diff(t)))
        hi = self.params()[0].upper
        lags = min(int(hi / dt), 40)
        tau = _fir_delay_memo(u, y, lags)
        if tau is None:
            tau, _ = equation_error_lag(u, y, lags)
        return {"tau": float(np.clip(tau * dt, 0.0, hi))}

    def signature(self, t, u, residual, dt):
        ud = rate_of(u, dt, smooth_seconds=5 * dt)
        c = corr(residual, ud)
        score = float(np.clip(-c, 0.0, 1.0))
        return score, (f"the residual is proportional to minus the input's rate (corr {c:+.2f}): the model "
                       f"moves before the measurement does, as with a delay of a few samples")


def _fir_delay_memo(u: np.ndarray, y: np.ndarray, lags: int) -> float | None:
    """:func:`_fir_delay`, remembered by the record's content: it depends on the record alone, and a diagnosis
    starts the delay at every refit that holds one (61 times on a 60k-sample record, 90 ms each)."""
    return _FIR_MEMO.get_or(content_key("fir_delay", u, y, lags), lambda: (_fir_delay(u, y, lags),))[0]


def _fir_delay(u: np.ndarray, y: np.ndarray, lags: int) -> float | None:
    """Delay in samples (fractional) from the FIR least-squares response of Δy to Δu, or None if unresolved.

    Returns None when the response has no clear peak (its largest tap below half the sum of the positive taps
    near it). Where the regression is ill-conditioned (band-limited inputs: neighbouring lags hard to tell apart)
    it is solved with a ridge of :data:`FIR_RIDGE` (of the unit diagonal), which widens the peak: there the
    largest tap must stand at least twice above every tap more than 3 lags from it, or None. Without the ridge
    the delay came from the base model's residual, and a base fitted without the delay has imitated part of it
    with its δ terms (generated GMA record, 14.3-sample output delay on band-limited noise: the residual said
    6.6 samples and every refit stayed there, 1.3x the noise; the ridge response peaks at 14).
    """
    du, dy = np.diff(u), np.diff(y)
    n = du.size
    if lags < 1 or n < 20 * (lags + 1):
        return None
    X = np.lib.stride_tricks.sliding_window_view(np.concatenate([np.zeros(lags), du]), lags + 1)[:, ::-1]
    G = X.T @ X
    d = np.sqrt(np.diag(G))
    if not np.all(d > 0):
        return None
    Gn = G / np.outer(d, d)
    ridge = np.linalg.cond(Gn) > FIR_COND_MAX
    h = np.linalg.solve(Gn + (FIR_RIDGE * np.eye(lags + 1) if ridge else 0.0), (X.T @ dy) / d) / d
    k = int(np.argmax(h))
    if h[k] <= 0 or k == lags:  # at the last tap the peak is cut off, not found
        return None
    lo, hi = h[k - 1] if k > 0 else 0.0, h[k + 1] if k < lags else 0.0
    if ridge:
        far = np.abs(np.r_[h[: max(k - 3, 0)], h[k + 4:]])
        if far.size and h[k] < 2.0 * far.max():
            return None
    else:
        near = h[max(k - 2, 0): k + 3]
        if h[k] < 0.5 * near[near > 0].sum():
            return None
    return _interpolate_peak(k, float(h[k]), float(lo), float(hi))


def _interpolate_peak(k: int, hk: float, lo: float, hi: float) -> float:
    """Fractional lag of a peak at ``k`` from its neighbours (linear interpolation splits a delay between two)."""
    if hi >= lo and hi > 0:
        return k + hi / (hk + hi)
    if lo > 0:
        return k - lo / (hk + lo)
    return float(k)


class DelayPredictor(OnlineEffect):
    """Smith predictor for a transport delay τ: the controller sees the measurement plus the base model's
    undelayed minus delayed prediction (what the stage would read now without the delay, corrected by every
    model error the delayed measurement shows), and aims at the reference τ ahead (:attr:`preview`).

    Parameters
    ----------
    tau : float
        Delay (s).
    dt : float
        Sample period (s).
    side : {"input", "output"}
        Where the delay acts (:class:`Delay`): on the input, the delayed prediction runs the base model on the
        delayed input; on the output, it is the undelayed prediction delayed.
    base : callable
        Makes a fresh per-sample base model (:class:`~hyst_model.effects.online.Stepper`).
    """

    name = "delay"

    smith = predictive = True

    def __init__(self, tau: float, dt: float, side: str, base) -> None:
        self.preview = tau
        d = tau / dt
        self._k0 = int(np.floor(d))
        self._frac = d - self._k0
        self._hist = np.zeros(self._k0 + 2)  # input (input side) or prediction (output side), newest first
        self._side = side
        self._now = base()
        self._late = base() if side == "input" else None
        self._fwd = np.zeros(self._k0 + 2)  # the chain's predicted measurement (forward), newest first

    def reset(self, y, u):
        x0 = self._now.reset(u)
        if self._late is not None:
            self._late.reset(u)
            self._hist[:] = u
        else:
            self._hist[:] = x0
        self._fwd[:] = x0

    def _delayed(self, h: np.ndarray | None = None) -> float:
        h = self._hist if h is None else h
        return (1.0 - self._frac) * h[self._k0] + self._frac * h[self._k0 + 1]

    def start(self, x, u):
        self._fwd[:] = x

    def forward(self, z, w, u, first):
        if first and self._late is not None:  # innermost on the input side: the base on the delayed input, exact
            self._hist[1:] = self._hist[:-1]
            self._hist[0] = u
            return self._late.step(self._delayed()), w
        self._fwd[1:] = self._fwd[:-1]
        self._fwd[0] = z
        return self._delayed(self._fwd), w

    def measure(self, y, u):
        x_now = self._now.step(u)
        self._hist[1:] = self._hist[:-1]
        if self._late is not None:
            self._hist[0] = u
            x_late = self._late.step(self._delayed())
        else:
            self._hist[0] = x_now
            x_late = self._delayed()
        return y + x_now - x_late
