"""Asymmetry: an even-order term that bends the hysteresis loop (rising and falling halves differ in shape).

The Bouc-Wen/MBW loop is point-symmetric about its centre: odd in the input change. Real piezo stacks and
magnetostrictive actuators show loops that are fatter or steeper at one end (Wang et al.'s asymmetric BW,
quadratic domain switching). The simplest physical extension is an even-order (quadratic) term in the
normalised input and in the hysteretic output, added to the output:

    y = y_inner + y_scale · (a_u · ũ² + a_y · ỹ²),   ũ = (u − u_c)/u_scale,  ỹ = (y_inner − y_c)/y_scale

with centres ``u_c``, ``y_c`` fixed at the middle of the identification data (stored in the params file as
``asymmetry.u_c``, ``asymmetry.y_c``) so the term is symmetric-free of the linear gain the base already fits.
"""
from __future__ import annotations

import math

import numpy as np

from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .signals import corr

__all__ = ["Asymmetry", "AsymmetryInverse"]


class Asymmetry(Effect):
    """Quadratic (even-order) input and output terms."""

    name = "asymmetry"
    summary = "loop bent to one side: an even-order (quadratic) term in input and output"
    physics = ("The loop is steeper or fatter at one end of the stroke than at the other; a symmetric hysteresis "
               "model cannot bend that way, a quadratic term can.")
    kind = "output"

    def __init__(self, config=None):
        super().__init__(config)
        self.u_c = float(self._config.get("asymmetry.u_c", 0.0))
        self.y_c = float(self._config.get("asymmetry.y_c", 0.0))

    def params(self):
        return (Param("a_u", 0.0, -0.5, 0.5, "", "quadratic term in the input, per normalised input unit²"),
                Param("a_y", 0.0, -0.5, 0.5, "", "quadratic term in the hysteretic output, per output unit²"))

    def config(self):
        return {"u_c": self.u_c, "y_c": self.y_c}

    def output(self, theta, t, u, y):
        uu = (np.asarray(u, float) - self.u_c) / self.u_scale
        yy = (y - self.y_c) / self.y_scale
        return y + self.y_scale * (theta[0] * uu * uu + theta[1] * yy * yy)

    def online(self, theta, base=None):
        return AsymmetryInverse(float(theta[0]), float(theta[1]), self.u_c, self.y_c, self.u_scale, self.y_scale)

    def start(self, t, u, y, residual):
        # Centre on the data, then regress the residual on the even input term.
        self.u_c = 0.5 * (float(np.min(u)) + float(np.max(u)))
        self.y_c = 0.5 * (float(np.min(y)) + float(np.max(y)))
        q = ((np.asarray(u, float) - self.u_c) / self.u_scale) ** 2
        q = q - q.mean()
        den = float(q @ q)
        return {"a_u": float(q @ (residual - residual.mean()) / den / self.y_scale)} if den > 0 else {}

    def signature(self, t, u, residual, dt):
        uc = 0.5 * (float(np.min(u)) + float(np.max(u)))
        q = (np.asarray(u, float) - uc) ** 2
        c = corr(residual, q)
        c_odd = corr(residual, np.asarray(u, float) - uc)
        score = float(np.clip(abs(c) - 0.5 * abs(c_odd), 0.0, 1.0))
        end = "both ends" if c > 0 else "the middle"
        return score, (f"the residual is an even function of the input: it has the same sign at both ends of the "
                       f"stroke and the opposite sign in the middle (corr with (u-u_mid)² = {c:+.2f}, "
                       f"with u = {c_odd:+.2f}); the measurement sits higher at {end} → asymmetric loop")


class AsymmetryInverse(OnlineEffect):
    """The quadratic terms inverted per sample: with z = (x − y_c)/y_scale and q = a_u·ũ² − (y − y_c)/y_scale the
    output equation is a_y·z² + z + q = 0; the root on the identity branch is z = −2q / (1 + √(1 − 4·a_y·q)).
    Beyond the fold (1 − 4·a_y·q < 0) no x gives y: the fold itself (z = −1/(2·a_y)) is returned."""

    name = "asymmetry"

    def __init__(self, a_u: float, a_y: float, u_c: float, y_c: float, u_scale: float, y_scale: float) -> None:
        self._au, self._ay, self._uc, self._yc = a_u, a_y, u_c, y_c
        self._us, self._ys = u_scale, y_scale

    def _inner(self, y: float, u: float) -> float:
        uu = (u - self._uc) / self._us
        q = self._au * uu * uu - (y - self._yc) / self._ys
        disc = 1.0 - 4.0 * self._ay * q
        z = -2.0 * q / (1.0 + math.sqrt(disc)) if disc >= 0.0 else -1.0 / (2.0 * self._ay)
        return self._yc + self._ys * z

    def measure(self, y, u):
        return self._inner(y, u)

    def target(self, r, u):
        return self._inner(r, u)
