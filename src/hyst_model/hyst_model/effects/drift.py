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
(a disturbance observer).

Where the offset drifts a record cannot tell (the reading is the same), so the user says it (``drift.side``):

``stage`` (default; a params file without the key)  the stage itself moves (thermal expansion of the mechanics):
    the reading is the position, and the feedback laws put the *reading* on the reference — the estimate is removed
    from measurement and reference alike. The open-loop inverse, which reads no sensor, cannot follow it.
``sensor``  the sensor's offset drifts (its electronics warm up) and the stage does not: the feedback laws put
    the stage's *position* — the reading minus the estimated offset — on the reference, and the reading shows the
    drift. The open-loop inverse then needs no sensor for it: the stage goes where the model sends it.

Identification and simulation are the same for both (the model's output is the reading either way).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import EffectError
from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .operators import plays
from .signals import corr, smooth

__all__ = ["Drift", "DriftObserver", "SPACINGS", "SIDES", "OBSERVER_TAU", "MAX_KNOTS", "RECORD_PLAYS", "RECORD_GAIN"]

#: Time constant (s) of the drift observer: long against the loop's own error dynamics (a few ms), so the estimate
#: takes no part in them and passes little sensor noise (about sqrt(dt/2τ) of it: 7 % at 2 kHz), short against a
#: thermal drift (tens of seconds). A ramp r leaves r·τ on the estimate (2.5 nm at 50 nm/s), of which the laws
#: see only a fraction (DPPC: (1 − δ1)·r·τ, since e = y − r is the same with the offset removed from both).
OBSERVER_TAU = 0.05

#: Knot spacings over the span: even, or denser at the start (quadratic).
SPACINGS = ("even", "early")

#: Knots at most: each is a parameter, and each segment must still be seconds long to predict held-out data.
MAX_KNOTS = 100

#: Play operators of the hysteresis the record start regresses on (radii evenly up to half the input's range).
RECORD_PLAYS = 20

#: The factor a drift read from the record must cut that record's hysteresis error by (``hyst diagnose``'s own
#: ``min_factor`` default: the standard an effect must meet against the model below it).
RECORD_GAIN = 1.1

#: Where the offset drifts (``drift.side``): the stage moves, or the sensor's reading does (module docstring).
SIDES = ("stage", "sensor")


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
        knots = float(self._config.get("drift.knots", 5))
        # 0 and -1 ended in an IndexError, 2.5 ran as 2, 1000 ran for minutes
        if not (math.isfinite(knots) and knots == int(knots) and 1 <= knots <= MAX_KNOTS):
            raise EffectError(f"drift.knots must be a whole number between 1 and {MAX_KNOTS}, not {knots:g}")
        self.knots = int(knots)
        self.span = float(self._config.get("drift.span", 0.0) or 0.0)
        if not (math.isfinite(self.span) and self.span >= 0.0):  # nan was fitted with and written back
            raise EffectError(f"drift.span must be a duration ≥ 0 s (0: the record's own), not {self.span:g}")
        self.spacing = str(self._config.get("drift.spacing", "even"))
        if self.spacing not in SPACINGS:
            raise EffectError(f"drift.spacing must be one of {', '.join(SPACINGS)}, not {self.spacing!r}")
        self.side = str(self._config.get("drift.side", "stage"))
        if self.side not in SIDES:
            raise EffectError(f"drift.side must be one of {', '.join(SIDES)} (what drifts: the stage, or the "
                              f"sensor's offset), not {self.side!r}")

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
        return {"knots": float(self.knots), "span": self.span, "spacing": self.spacing, "side": self.side}

    def _nodes(self, t):
        span = self.span if self.span > 0 else float(t[-1] - t[0])
        x = np.linspace(0.0, 1.0, self.knots + 1)
        return float(t[0]) + span * (x * x if self.spacing == "early" else x)

    def online(self, theta, base=None):
        """A disturbance observer of the offset (:class:`DriftObserver`); the fitted knots are not used."""
        if base is None:
            return None
        return DriftObserver(self.dt, OBSERVER_TAU, base, follow_reading=self.side == "stage")

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

    #: Undone only at the record start: the residual start is what a base that absorbed the drift left of it, and
    #: refitting the base around that moved it off the rung's point (generated PEA stage 3000102, creep and a kink:
    #: the ladder ended at 1.52× the noise floor instead of 1.15×).
    undo_at_own_start = False

    def undo_output(self, theta, t, u, y):
        """The reading without the drift at ``theta``: the base fitted on it is not bent towards the drift (see
        :meth:`record_start`)."""
        return np.asarray(y, dtype=np.float64) - self.output(theta, t, u, np.zeros(np.shape(y)))

    def record_start(self, t, u, y, scored):
        """The drift read from the record alone: least squares of the reading on a hysteresis of the input — play
        operators (:data:`RECORD_PLAYS` radii up to half its range), its square and cube, a constant — and this
        spline, over the ``scored`` samples.

        A base fitted without the drift can absorb it: on a generated GMA staircase with a linear drift of 35× the
        noise, the base's δ1 and δ2 went to their bound 1 (an integrating loop), its residual showed no trend (the
        start from it: −15…2 nm where the drift reaches 124 nm) and every refit ended at 13× the noise floor; from
        this start the base refitted around it and the joint fit reached the floor. Where the input repeats its
        levels a rate-independent hysteresis of it is the same on every visit, so what differs in time is the drift.
        None where the spline does not cut that regression's error by :data:`RECORD_GAIN` (the record shows no
        drift this way) or the input never moves.
        """
        u = np.asarray(u, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        scored = np.asarray(scored, dtype=bool)
        span = float(np.ptp(u))
        if not (span > 0 and scored.sum() > 4 * (RECORD_PLAYS + self.knots + 3)):
            return None
        if self.span <= 0:
            self.span = float(t[-1] - t[0])
        un = np.ascontiguousarray((u - u.min()) / span)
        P = plays(un, np.arange(RECORD_PLAYS) * (0.5 / RECORD_PLAYS))
        zero = np.zeros_like(y)
        eye = np.eye(self.knots)
        B = np.column_stack([self.output(eye[j], t, u, zero) for j in range(self.knots)])
        F = np.column_stack([P, un * un, un * un * un, np.ones_like(un), B])[scored]
        sd = F.std(axis=0)
        sd[sd == 0] = 1.0
        F /= sd
        ys = y[scored]
        coef, *_ = np.linalg.lstsq(F, ys, rcond=None)
        without, *_ = np.linalg.lstsq(F[:, :-self.knots], ys, rcond=None)
        r_with = float(np.sqrt(np.mean((ys - F @ coef) ** 2)))
        r_without = float(np.sqrt(np.mean((ys - F[:, :-self.knots] @ without) ** 2)))
        # Only a drift the record shows: the spline must cut that hysteresis's error as any effect must cut the
        # model below it; otherwise it holds what the hysteresis misses (creep, a delay: −0.3…−0.9 µm "drifts" on
        # the 60 s benchmark record, whose spline took 1 % of the error) and the refit from it is wasted.
        if not (r_with > 0 and r_without >= RECORD_GAIN * r_with):
            return None
        c = coef[-self.knots:] / sd[-self.knots:]
        if not np.all(np.isfinite(c)):
            return None
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
    the offset is still unexplained. :meth:`measure` removes ``d̂``; with ``follow_reading`` (the stage drifts)
    :meth:`target` does too, so the law tracks the base model's output that puts the *measured* output on the
    reference, whatever the stage drifted by; without it (the sensor drifts) the reference is left as it is, so the
    law puts the measurement minus the offset — the stage's position — on it.
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
    follow_reading : bool
        True (``drift.side: stage``): the reading follows the reference; False (``sensor``): the position does.
    """

    name = "drift"
    #: In a compensation's prediction chain the drift adds its offset estimate to what lies inside it, so a Smith
    #: predictor outside it is predicted as one chain with it (an inner drift that broke the chain left DPPC on
    #: its own model with a delay and a 350 Hz mode unstable, DMRAC 246 nm off on a 30 Hz sine).
    predictive = True

    def __init__(self, dt: float, tau: float, base, follow_reading: bool = True) -> None:
        if not (dt > 0 and tau > 0):
            raise ValueError("the drift observer needs dt > 0 and tau > 0")
        self.follow_reading = bool(follow_reading)
        # the open-loop inverse cannot follow a moving stage without a reading; a drifting sensor it need not
        self.needs_sensor = self.follow_reading
        # an alpha-beta (offset and rate) filter, both poles at 1 − dt/τ (critically damped): a ramp leaves no
        # steady lag (a first-order observer kept rate·τ, 10 nm at 200 nm/s, which a sensor-side drift puts on
        # the stage's position); it passes about 11 % of the sensor noise at 2 kHz against 7 %
        lam = 1.0 - min(1.0, dt / tau)
        self._alpha, self._beta = 1.0 - lam * lam, (1.0 - lam) ** 2
        self.slope = 0.0
        self._model = base()
        self._pred = float("nan")
        self.offset = 0.0

    def reset(self, y, u):
        self._pred = self._model.reset(u)
        self.offset = self.slope = 0.0

    def measure(self, y, u):
        self._pred = self._model.step(u)
        return y - self.offset

    def forward(self, z, w, u, first):
        return z + self.offset, w + self.offset

    def observe(self, x, u):
        innovation = x - self._pred
        if np.isfinite(innovation):  # a bad sample or a diverged prediction must not poison the estimate
            self.slope += self._beta * innovation
            self.offset += self._alpha * innovation + self.slope  # corrected, then predicted a sample on

    def target(self, r, u):
        return r - self.offset if self.follow_reading else r
