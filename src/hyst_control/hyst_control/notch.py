"""A notch filter on a command: the stage resonance taken out of what a model-free law (PID) sends.

Commercial piezo controllers put a notch at the flexure resonance instead of slowing the whole loop down. The
filter here is the classic second-order notch

    N(s) = (s² + 2·ζz·ω·s + ω²) / (s² + 2·ζp·ω·s + ω²),     ω = 2π·fn,

unit gain at DC and far from ω, depth ζz/ζp at ω. With ζz the mode's own damping its zeros cancel the mode's
poles and put back a mode damped by ζp: a lightly damped peak becomes a well-damped one. Discretised by the
bilinear transform prewarped at ω (the notch sits exactly at fn at any sample rate below 2·fn), coefficients in
q = z⁻¹ as :mod:`hyst_control.loop_tf` uses them. :class:`Notch` runs it per sample (transposed direct form II)
and starts in steady state, so switching it in does not kick the command.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError

__all__ = ["notch_tf", "Notch", "NYQUIST_SHARE"]

#: A notch above this share of the Nyquist frequency is refused: the prewarped map folds its width there.
NYQUIST_SHARE = 0.9


def notch_tf(fn: float, zeta_zero: float, zeta_pole: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of the discretised notch in q (index = power), ``den[0] = 1``, unit DC gain.

    Raises
    ------
    ConfigError
        fn not positive or at or above :data:`NYQUIST_SHARE` of Nyquist; a damping not in (0, 10].
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ConfigError("a notch needs a positive sample period")
    if not (math.isfinite(fn) and 0.0 < fn < NYQUIST_SHARE * 0.5 / dt):
        raise ConfigError(f"a notch needs 0 < fn < {NYQUIST_SHARE:g} x the Nyquist frequency "
                          f"({NYQUIST_SHARE * 0.5 / dt:g} Hz), got {fn:g} Hz")
    for name, z in (("zeta_zero", zeta_zero), ("zeta_pole", zeta_pole)):
        if not (math.isfinite(z) and 0.0 < z <= 10.0):
            raise ConfigError(f"notch {name} must lie in (0, 10], got {z:g}")
    w = 2.0 * math.pi * fn
    k = w / math.tan(0.5 * w * dt)  # s = k(1 − q)/(1 + q), prewarped at ω

    def quad(zeta: float) -> np.ndarray:  # (s² + 2ζωs + ω²)·(1 + q)²
        return np.array([k * k + 2 * zeta * w * k + w * w, 2 * (w * w - k * k), k * k - 2 * zeta * w * k + w * w])

    num, den = quad(zeta_zero), quad(zeta_pole)
    return num / den[0], den / den[0]


class Notch:
    """The notch per sample: ``y = step(x)``; :meth:`reset` sets the steady state for a constant input."""

    def __init__(self, fn: float, zeta_zero: float, zeta_pole: float, dt: float) -> None:
        self.fn, self.zeta_zero, self.zeta_pole = float(fn), float(zeta_zero), float(zeta_pole)
        self.num, self.den = notch_tf(fn, zeta_zero, zeta_pole, dt)
        self._s1 = self._s2 = 0.0

    def reset(self, x0: float) -> None:
        """Steady state for the input held at ``x0`` (the output is then ``x0``: unit DC gain)."""
        b, a = self.num, self.den
        self._s2 = (b[2] - a[2]) * x0
        self._s1 = (b[1] - a[1]) * x0 + self._s2

    def step(self, x: float) -> float:
        b, a = self.num, self.den
        y = b[0] * x + self._s1
        self._s1 = b[1] * x - a[1] * y + self._s2
        self._s2 = b[2] * x - a[2] * y
        return y
