"""Drift: an input-independent slow change of the output offset (thermal expansion, sensor drift).

Temperature changes of the stage or the sensor electronics move the reading without any input change: a trend,
slow thermal swings and a random walk. The effect adds a piecewise-linear spline in time, zero at the start of
the record (the base model's ``offset`` carries the constant), with ``K`` knots over the identification span
(``drift.knots``, default 5; ``drift.span`` in s is stored with the fit):

    y = y_inner + d(t),   d = linear interpolation of (0, c1, …, cK) at t_j = t_0 + span·s(j/K),
    continued with the last segment's slope beyond the span

spread evenly (``drift.spacing: even``, s(x) = x, what a params file without the key means) or denser at the start
(``early``, s(x) = x²: knots at 4 %, 16 %, 36 %, 64 % of the span) for a reading that settles after switch-on — an
exponential warm-up of 0.05–1 s in an 8 s record fell between the even knots and was absorbed by the base's
offset and δ terms. ``hyst diagnose`` fits both (:meth:`Drift.variants`) and keeps whichever validates better.

(c_j in metres). Drift cannot be predicted from the input: beyond the span only its trend carries on, so keep
``knots`` small (each segment several seconds long) when the model must predict held-out data.
"""
from __future__ import annotations

import numpy as np

from ..errors import EffectError
from ..model import Param
from .base import Effect
from .signals import corr, smooth

__all__ = ["Drift", "SPACINGS"]

#: Knot spacings over the span: even, or denser at the start (quadratic).
SPACINGS = ("even", "early")


class Drift(Effect):
    """Piecewise-linear offset drift in time."""

    name = "drift"
    summary = "slow input-independent offset drift (temperature, sensor electronics)"
    physics = ("The reading wanders slowly over the record even where the input repeats itself; the model's "
               "error at the same input level differs between early and late in the record.")
    kind = "output"
    online_note = ("an input-independent offset trend tied to the identification record's clock: nothing to invert "
                   "at run time; the feedback removes a slow offset (not compensated)")

    def __init__(self, config=None):
        super().__init__(config)
        self.knots = int(float(self._config.get("drift.knots", 5)))
        self.span = float(self._config.get("drift.span", 0.0) or 0.0)
        self.spacing = str(self._config.get("drift.spacing", "even"))
        if self.spacing not in SPACINGS:
            raise EffectError(f"drift.spacing must be one of {', '.join(SPACINGS)}, not {self.spacing!r}")

    @staticmethod
    def variants() -> list[dict[str, str]]:
        """Configurations ``hyst diagnose`` tries, keeping whichever validates better: both knot spacings."""
        return [{"drift.spacing": s} for s in SPACINGS]

    @classmethod
    def data_config(cls, t, u, y, scored):
        """Knots over the span the fit scores (beyond it only the trend carries on)."""
        ts = np.asarray(t, float)[np.asarray(scored, bool)]
        return {"drift.span": float(ts[-1] - t[0])} if ts.size else {}

    def params(self):
        b = float(self._config.get("offset_bound", 1e-3)) + 50.0 * self.y_scale
        return tuple(Param(f"c{j}", 0.0, -b, b, "m", f"offset change at knot {j} of {self.knots}")
                     for j in range(1, self.knots + 1))

    def config(self):
        return {"knots": float(self.knots), "span": self.span, "spacing": self.spacing}

    def _nodes(self, t):
        span = self.span if self.span > 0 else float(t[-1] - t[0])
        x = np.linspace(0.0, 1.0, self.knots + 1)
        return float(t[0]) + span * (x * x if self.spacing == "early" else x)

    def output(self, theta, t, u, y):
        vals = np.concatenate([[0.0], np.asarray(theta, float)])
        nodes = self._nodes(t)
        d = np.interp(t, nodes, vals)
        beyond = t > nodes[-1]
        if beyond.any():  # continue the last segment's trend past the identification span
            slope = (vals[-1] - vals[-2]) / (nodes[-1] - nodes[-2])
            d[beyond] += slope * (t[beyond] - nodes[-1])
        return y + d

    def start(self, t, u, y, residual):
        if self.span <= 0:
            self.span = float(t[-1] - t[0])
        nodes = self._nodes(t)
        # Least squares of the residual on the hat functions (first one dropped: the offset is the base's).
        eye = np.eye(self.knots + 1)
        B = np.vstack([np.interp(t, nodes, eye[j]) for j in range(self.knots + 1)]).T
        coef, *_ = np.linalg.lstsq(B, residual, rcond=None)
        c = coef[1:] - coef[0]
        return {f"c{j}": float(c[j - 1]) for j in range(1, self.knots + 1)}

    def signature(self, t, u, residual, dt):
        n = residual.size
        slow = smooth(residual, max(1, int(round(2.0 / dt))))  # 2 s moving average
        tot = float(((residual - residual.mean()) ** 2).sum())
        r2 = float(((slow - slow.mean()) ** 2).sum()) / tot if tot > 0 else 0.0
        cu = abs(corr(slow, smooth(u, max(1, int(round(2.0 / dt))))))
        score = float(np.clip(r2 * (1.0 - cu), 0.0, 1.0))
        span = float(np.ptp(slow)) if n else 0.0
        return score, (f"the residual wanders slowly ({min(r2, 1.0):.0%} of it is slower than 2 s) and does not "
                       f"follow the input (corr {cu:.2f}); the reading drifts by {span * 1e9:.3g} nm over the record")
