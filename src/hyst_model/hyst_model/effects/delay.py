"""Delay: a transport delay between the applied input and the measured output.

Amplifier filters, sensor electronics and sample-and-hold stages delay the measurement by a fraction of a
millisecond to a few milliseconds. A hysteresis model without it leads the measurement, so its residual is
proportional to minus the output's rate: ε(t) ≈ −τ·ẏ(t). The effect shifts the input by τ seconds
(fractional samples by linear interpolation; before the record starts the input is held at u[0]).
"""
from __future__ import annotations

import numpy as np

from ..model import Param
from .base import Effect
from .signals import corr, rate_of

__all__ = ["Delay"]


class Delay(Effect):
    """Input transport delay τ (s), fractional samples by linear interpolation."""

    name = "delay"
    summary = "input-to-output transport delay (amplifier and sensor electronics)"
    physics = ("The measurement lags the model by a fixed time: the error is largest where the output moves "
               "fastest and has the opposite sign of the output's rate.")
    kind = "input"

    def params(self):
        return (Param("tau", 0.0, 0.0, max(0.05, 50 * self.dt), "s", "transport delay from input to output"),)

    def input(self, theta, t, u):
        tau = float(theta[0])
        if tau <= 0.0:
            return u
        return np.interp(t - tau, t, u, left=u[0])

    def start(self, t, u, y, residual):
        # The model x = y − residual leads the measurement: y(t) ≈ x(t − τ). Search τ on a grid of samples.
        t = np.asarray(t, float)
        x = np.asarray(y, float) - residual
        dt = float(np.median(np.diff(t)))
        hi = self.params()[0].upper
        best_tau, best = 0.0, float(residual @ residual)
        for k in range(1, int(hi / dt) + 1):
            xs = np.concatenate([np.full(k, x[0]), x[:-k]])
            c = float(((y - xs) ** 2).sum())
            if c < best:
                best_tau, best = k * dt, c
        return {"tau": best_tau}

    def signature(self, t, u, residual, dt):
        ud = rate_of(u, dt, smooth_seconds=5 * dt)
        c = corr(residual, ud)
        score = float(np.clip(-c, 0.0, 1.0))
        return score, (f"the residual is proportional to minus the input's rate (corr {c:+.2f}): the model "
                       f"moves before the measurement does, as with a delay of a few samples")
