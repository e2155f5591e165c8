"""Saturation: a smooth limit of the stroke at its end(s) (output side).

Preloaded stacks and flexure stages stiffen near the end of their travel, and amplifiers and sensors compress
near the end of their range, so large displacements fall short of what the hysteresis model predicts — more
the further out. The effect is the identity inside a knee and a tanh soft limit beyond it (C¹ at the knee):

    y = k_hi + w · tanh((x − k_hi) / w)   for x > k_hi = top − w        (x = y_inner)
    y = k_lo − w · tanh((k_lo − x) / w)   for x < k_lo = bottom + w      (two-sided only)

``top`` and ``bottom`` (m) are the asymptotic limits, ``w`` (m) the knee width. Two-sided knees never overlap:
the width acting is ``min(w, (top − bottom)/2)`` (:func:`knee_width`), so a strong limit — more than a sixth of
the stroke lost at each end with knees twice as wide as the loss — has its knees meet at mid-range, where both
branches have slope 1 (the map stays monotonic and C¹). Overlapping knees made the map a different function
depending on which branch was evaluated last: hyst_sim took the upper one, this effect the lower one, and two
generated GMA stages (0.19 of the stroke lost at each end) could not be fitted below 22x their noise.

A stage may saturate at the top only (a preloaded stack driven against its stop) or at both ends (a flexure
stiffening both ways, a sensor's range, and an amplifier's rails whatever the sign of its input):
``saturation.two_sided`` is configuration stored in the params file. ``hyst diagnose`` fits both
(:meth:`Saturation.variants`) and keeps whichever validates better; without it being set, :meth:`Saturation.start`
guesses from the input's sign (bipolar: both ends) — the guess alone missed the lower knee of unipolar piezo records
with a symmetric soft limit, which then took an asymmetry to imitate it.
"""
from __future__ import annotations

import math

import numpy as np

from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .signals import corr, midrange

__all__ = ["Saturation", "SaturationInverse", "soft_limit", "knee_width"]


def knee_width(top: float, bottom: float, w: float, two_sided: bool) -> float:
    """The knee width acting: ``w``, but at most half the distance between two-sided limits (the knees meet at
    mid-range instead of overlapping; see the module docstring). Limits in the wrong order keep ``w`` (the upper
    branch then takes precedence, as everywhere below)."""
    if two_sided and top > bottom:
        return min(w, 0.5 * (top - bottom))
    return w


def soft_limit(x: np.ndarray, top: float, bottom: float, w: float, two_sided: bool) -> np.ndarray:
    """The saturation map (see module docstring)."""
    x = np.asarray(x, dtype=np.float64)
    y = x.copy()
    w = knee_width(top, bottom, w, two_sided)
    k = top - w
    up = x > k
    y[up] = k + w * np.tanh((x[up] - k) / w)
    if two_sided:
        k = bottom + w
        m = (x < k) & ~up
        y[m] = k - w * np.tanh((k - x[m]) / w)
    return y


class Saturation(Effect):
    """Smooth stroke limit with a linear core and tanh knees."""

    name = "saturation"
    summary = "smooth saturation: the stroke falls short at the end(s) of the travel"
    physics = ("Near the end of the travel the measured displacement falls short of the model, more the larger "
               "the excursion: a flexure/preload stiffening, or an amplifier or sensor range limit.")
    kind = "output"
    pointwise = True

    def __init__(self, config=None):
        super().__init__(config)
        self.two_sided = bool(float(self._config.get("saturation.two_sided", 0.0)))
        self._two_sided_set = "saturation.two_sided" in self._config
        self.bound = float(self._config.get("offset_bound", 1e-3)) + 50.0 * self.y_scale

    def params(self):
        b = self.bound
        return (Param("top", b, -b, b, "m", "upper displacement limit (asymptote)"),
                Param("bottom", -b, -b, b, "m", "lower displacement limit (two-sided only)"),
                Param("width", self.y_scale, 1e-3 * self.y_scale, 20.0 * self.y_scale, "m", "knee width"))

    def config(self):
        return {"two_sided": float(self.two_sided)}

    @staticmethod
    def variants() -> list[dict[str, float]]:
        """Configurations ``hyst diagnose`` tries, keeping whichever validates better: top only, both ends."""
        return [{"saturation.two_sided": 0.0}, {"saturation.two_sided": 1.0}]

    def output(self, theta, t, u, y):
        top, bottom, w = float(theta[0]), float(theta[1]), float(theta[2])
        return soft_limit(y, top, bottom, w, self.two_sided)

    def settle(self, theta, x):
        """Each limit of a two-sided saturation whose knee no sample of the inner output ``x`` enters is moved out
        to half the limits' range (the acting knee width kept): the same output on the record, bit for bit, and no
        stop where the record shows none (:mod:`.settle`). A one-sided limit is left as fitted."""
        top, bottom, w = (float(v) for v in theta)
        if not self.two_sided or not np.all(np.isfinite(x)):
            return theta
        we = knee_width(top, bottom, w, True)
        if not (top > bottom and self.params()[2].lower <= we):
            return theta
        lo, hi = float(np.min(x)), float(np.max(x))
        # half the limits' range: 25 stroke scales out, beyond any travel, and not on the bound (which reports a
        # fit stuck there)
        b = 0.5 * self.bound
        out = np.array(theta, dtype=np.float64)
        if lo >= bottom + we:  # the lower branch is taken only below its knee
            out[1], out[2] = -b, we
        if hi <= top - we:  # the upper one likewise
            out[0], out[2] = b, we
        return out

    def online(self, theta, base=None):
        return SaturationInverse(float(theta[0]), float(theta[1]), float(theta[2]), self.two_sided)

    def start(self, t, u, y, residual):
        if not self._two_sided_set:  # a guess from the input's sign where the configuration does not say
            self.two_sided = bool(np.min(u) < -0.05 * np.max(np.abs(u)))
        x = np.asarray(y, float) - residual  # ≈ base model output
        lo, hi = float(np.min(x)), float(np.max(x))
        span = hi - lo
        best = (float(residual @ residual), {})
        shaped = (math.inf, {})  # the knee whose shape the residual shows best, at whatever share of it
        for frac in (0.02, 0.05, 0.1, 0.2, 0.3, 0.5):
            for wf in (0.05, 0.1, 0.2, 0.4):
                w = wf * span
                top, bottom = hi - frac * span + w, lo + frac * span - w
                d = soft_limit(x, top, bottom, w, self.two_sided) - x
                den = float(d @ d)
                if den <= 0:
                    continue
                g = float(d @ residual) / den  # how much of this deficit the residual shows
                cost = float(((residual - d) ** 2).sum())
                if 0.5 < g < 2.0 and cost < best[0]:
                    best = (cost, {"top": top, "bottom": bottom, "width": w})
                c_shape = float(((residual - g * d) ** 2).sum())
                if g > 0.0 and c_shape < shaped[0]:
                    shaped = (c_shape, {"top": top, "bottom": bottom, "width": w})
        # No knee of the full size: a base that imitated part of the limit leaves only a share of it (generated GMA
        # stage 1119: psi2 < 0 and alpha2 > 0 bent the base's loop). The default limits, far outside the stroke,
        # have no gradient and the fit never moved from them (708 nm on both sides of the refit); the knee with
        # the residual's shape gives the fit a start.
        return best[1] or shaped[1]

    def signature(self, t, u, residual, dt):
        uc = midrange(u)
        x = np.asarray(u, float) - uc
        xn = x / max(float(np.max(np.abs(x))), 1e-300)
        top = np.clip(xn - 0.5, 0.0, None) ** 2
        bot = np.clip(-xn - 0.5, 0.0, None) ** 2
        c = max(corr(residual, -top), corr(residual, -top + bot))
        score = float(np.clip(c, 0.0, 1.0))
        return score, (f"near the end of the stroke the measurement falls short of the model, more the further "
                       f"out (corr {c:+.2f} with a shortfall growing beyond the knee) → the travel saturates")


class SaturationInverse(OnlineEffect):
    """The soft limit inverted per sample: x = k + w·artanh((y − k)/w) beyond a knee k. A target at or beyond an
    asymptote cannot be reached: it is held at :attr:`REACH` of the way from the knee to the asymptote (the stage's
    limit is respected, not chased with an unbounded input) and counted in :attr:`limited`."""

    name = "saturation"
    #: Fraction of the knee width a target may reach (tanh(2.65) = 0.99: 2.65 widths into the knee).
    REACH = 0.99
    predictive = True

    def __init__(self, top: float, bottom: float, width: float, two_sided: bool) -> None:
        self._top, self._bot, self._two = top, bottom, two_sided
        self._w = knee_width(top, bottom, width, two_sided)
        self.limited = 0

    def _inner(self, y: float) -> float:
        w = self._w
        k = self._top - w
        if y > k:
            return k + w * math.atanh(min((y - k) / w, self.REACH))
        if self._two:  # below the upper knee: the lower branch (as soft_limit, the upper one first)
            k = self._bot + w
            if y < k:
                return k - w * math.atanh(min((k - y) / w, self.REACH))
        return y

    def _outer(self, x: float) -> float:
        w = self._w
        k = self._top - w
        if x > k:
            return k + w * math.tanh((x - k) / w)
        k = self._bot + w
        if self._two and x < k:
            return k - w * math.tanh((k - x) / w)
        return x

    def forward(self, z, w, u, first):
        return self._outer(z), self._outer(w)

    def measure(self, y, u):
        return self._inner(y)

    def target(self, r, u):
        lo, hi = self.bounds()
        if not lo < r < hi:
            self.limited += 1
        return self._inner(r)

    def bounds(self):
        span = self.REACH * self._w
        return (self._bot + self._w - span if self._two else -math.inf, self._top - self._w + span)
