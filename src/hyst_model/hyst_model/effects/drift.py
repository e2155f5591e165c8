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

For control the fitted spline is of no use (it is tied to the identification record's clock); what the model
identified is that the reading carries a slow input-independent offset. :class:`DriftObserver` estimates it at
run time from the sensor: the base-level measurement minus the base model's own prediction, low-pass filtered
(a disturbance observer), and the controllers run on measurement and reference with the estimate removed.
"""
from __future__ import annotations

import numpy as np

from ..errors import EffectError
from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .signals import corr, smooth

__all__ = ["Drift", "DriftObserver", "SPACINGS", "OBSERVER_TAU"]

#: Time constant (s) of the drift observer: long against the loop's own error dynamics (a few ms), so the estimate
#: takes no part in them and passes little sensor noise (about sqrt(dt/2τ) of it: 7 % at 2 kHz), short against a
#: thermal drift (tens of seconds). A ramp r leaves r·τ on the estimate (2.5 nm at 50 nm/s), of which the laws
#: see only a fraction (DPPC: (1 − δ1)·r·τ, since e = y − r is the same with the offset removed from both).
OBSERVER_TAU = 0.05

#: Knot spacings over the span: even, or denser at the start (quadratic).
SPACINGS = ("even", "early")


class Drift(Effect):
    """Piecewise-linear offset drift in time."""

    name = "drift"
    summary = "slow input-independent offset drift (temperature, sensor electronics)"
    physics = ("The reading wanders slowly over the record even where the input repeats itself; the model's "
               "error at the same input level differs between early and late in the record.")
    kind = "output"
    pointwise = True
    of_time = True
    online_note = ("an input-independent offset: estimated from the sensor (a disturbance observer), which needs "
                   "a measurement; the open-loop inverse has none and cannot remove it")

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

    def online(self, theta, base=None):
        """A disturbance observer of the offset (:class:`DriftObserver`); the fitted knots are not used."""
        if base is None:
            return None
        return DriftObserver(self.dt, OBSERVER_TAU, base)

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


class DriftObserver(OnlineEffect):
    """Disturbance observer for an output offset that drifts: ``d̂ ← d̂ + (dt/τ)·(x − x̂)``.

    ``x`` is the measurement after every effect's inverse (the base-level value the law sees, with ``d̂``
    already removed) and ``x̂`` the base model's prediction for the applied input, so the innovation is what of
    the offset is still unexplained. :meth:`measure` and :meth:`target` both remove ``d̂``: the law tracks the
    base model's output that puts the *measured* output on the reference, whatever the stage drifted by.
    The estimate starts at 0 (bumpless: no jump of the first command) and is updated only from sensor readings
    (:meth:`observe`, which the open-loop inverse does not call).

    Parameters
    ----------
    dt : float
        Loop period (s).
    tau : float
        Observer time constant (s), :data:`OBSERVER_TAU` by default.
    base : callable
        Makes a fresh per-sample base model (:class:`~hyst_model.effects.online.Stepper`).
    """

    name = "drift"
    needs_sensor = True

    def __init__(self, dt: float, tau: float, base) -> None:
        if not (dt > 0 and tau > 0):
            raise ValueError("the drift observer needs dt > 0 and tau > 0")
        self._gain = min(1.0, dt / tau)
        self._model = base()
        self._pred = float("nan")
        self.offset = 0.0

    def reset(self, y, u):
        self._pred = self._model.reset(u)
        self.offset = 0.0

    def measure(self, y, u):
        self._pred = self._model.step(u)
        return y - self.offset

    def observe(self, x, u):
        innovation = x - self._pred
        if np.isfinite(innovation):  # a bad sample or a diverged prediction must not poison the estimate
            self.offset += self._gain * innovation

    def target(self, r, u):
        return r - self.offset
