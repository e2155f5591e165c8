"""Baselines: a PID with anti-windup, and the open-loop inverse-model feedforward.

PID (SI gains): u = K_p·e + I + D with e = r − y,
I_k = I_{k−1} + Δt·(K_i·e_k + (u_sat − u_raw)/T_t)  (back-calculation anti-windup, T_t = ``t_track``),
D = derivative of −y (no kick on reference steps) through a first-order filter with time constant ``t_filter``.
With ``notch_fn`` > 0 the sum passes a notch (:mod:`hyst_control.notch`) before the limiter: the stage resonance
taken out of the command instead of every gain slowed down (the back-calculation sees the notched command).
Bumpless start: :meth:`PID.reset` preloads I so that the first output equals the command in force.

Open loop (:class:`OpenLoop`): the same one-step inversion as (4.11) with χ → 0, but driven by the model's own
predicted output instead of the measurement — the inverse-model feedforward the thesis's open-loop experiments
(Figs. 4.4–4.6) lack. The model state advances with :func:`hyst_model.core.mbw_step` on the applied command.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hyst_common.limits import CommandLimits
from hyst_common.params import param
from hyst_model.core import MBWParams, mbw_rest_state, mbw_step, pea_default

from .base import BaseController, ModelBased, invert_nu
from .errors import ConfigError
from .notch import Notch

__all__ = ["PIDGains", "PID", "OpenLoop", "gains_for", "static_gain", "feed_through"]


@dataclass(frozen=True)
class PIDGains:
    """PID gains in SI units.

    Defaults are tuned on the embedded PEA default (DC gain ≈ 0.2 µm/V, feed-through ≈ 0.15 µm/V) at 2 kHz for
    an integral gain of 0.8 per sample relative to the DC gain (K_i·Δt·0.2 µm/V), chosen from a grid over K_p,
    K_i as the best step/10 Hz/30 Hz compromise that still tolerates a 20 % gain error: an honest baseline.

    Attributes
    ----------
    kp : float
        V/m.
    ki : float
        V/(m·s).
    kd : float
        V·s/m.
    t_filter : float
        Derivative filter time constant (s).
    t_track : float
        Back-calculation time constant (s); smaller = faster unwinding.
    """

    kp: float = param(1.0e6, 0.0, 1e9, "proportional gain (V/m)")
    ki: float = param(8.0e9, 0.0, 1e13, "integral gain (V/(m s))")
    kd: float = param(0.0, 0.0, 1e6, "derivative gain (V s/m)")
    t_filter: float = param(2e-3, 1e-6, 1.0, "derivative filter time constant (s)")
    t_track: float = param(5e-3, 1e-6, 10.0, "anti-windup back-calculation time constant (s)")
    notch_fn: float = param(0.0, 0.0, 1e5, "notch on the command at this frequency (Hz; 0 = none); the stability "
                                           "check places one at an identified resonance (stability.notch)")
    notch_zeta_zero: float = param(0.05, 1e-4, 10.0, "notch zero damping (depth: zeta_zero/zeta_pole at fn)")
    notch_zeta_pole: float = param(0.5, 1e-4, 10.0, "notch pole damping (width)")

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) and v >= 0 for v in (self.kp, self.ki, self.kd)):
            raise ConfigError("PID gains must be finite and >= 0")
        if not (self.t_filter > 0 and self.t_track > 0):
            raise ConfigError("PID t_filter and t_track must be positive")
        if not (math.isfinite(self.notch_fn) and self.notch_fn >= 0):
            raise ConfigError("PID notch_fn must be finite and >= 0 (0 = no notch)")
        if not (0 < self.notch_zeta_zero <= 10 and 0 < self.notch_zeta_pole <= 10):
            raise ConfigError("PID notch dampings must lie in (0, 10]")

    def notch(self, dt: float) -> Notch | None:
        """The command notch these gains ask for at sample period ``dt`` (None without one)."""
        return Notch(self.notch_fn, self.notch_zeta_zero, self.notch_zeta_pole, dt) if self.notch_fn > 0 else None


def static_gain(model: MBWParams, v_min: float, v_max: float) -> float:
    """The model's quasi-static gain (m/V): rest displacement at ``v_max`` minus at ``v_min`` held, per volt
    (:func:`hyst_model.core.mbw_rest_state`); NaN where the model has no finite rest there."""
    p = model.vector
    lo, hi = (mbw_rest_state(p, v / model.u_scale) for v in (v_min, v_max))
    return float(model.y_scale * (hi - lo) / (v_max - v_min))


def feed_through(model: MBWParams) -> float:
    """The model's one-sample gain (m/V) about rest: ∂y_k/∂u_k of (3.21) at y = 0 and a slow input, ζ1 scaled."""
    return float(model.y_scale * model.zeta1 / model.u_scale)


def gains_for(model: MBWParams, v_min: float, v_max: float, gains: PIDGains | None = None) -> PIDGains:
    """``gains`` (default :class:`PIDGains`) moved from the embedded PEA stage to a stage of ``model``.

    K_p, K_i and K_d are scaled so that neither loop gain they were tuned for grows: the static one (the PEA's
    static gain over 0–150 V against the model's over ``[v_min, v_max]``, :func:`static_gain`) nor the one-sample
    one (:func:`feed_through`), which sets the loop near the Nyquist rate — the smaller factor of the two. About
    rest the MBW is the lead-lag ζ1(1 − δ2 z⁻¹)/(1 − δ1 z⁻¹), so a stage with a quicker memory (smaller δ1) than
    the PEA's has a feed-through above its static gain and rings at gains scaled by the static gain alone. A ±10 V
    stage of 1.9 µm/V with the PEA's SI gains rang at ten times their loop gain. Unchanged where a gain of the
    model is not finite and positive.
    """
    g = gains or PIDGains()
    pea = pea_default()
    k = []
    for own, ref in ((static_gain(model, v_min, v_max), static_gain(pea, 0.0, 150.0)),
                     (feed_through(model), feed_through(pea))):
        if not (math.isfinite(own) and own > 0.0):
            return g
        k.append(ref / own)
    f = min(k)
    return replace(g, kp=g.kp * f, ki=g.ki * f, kd=g.kd * f)


def _notch_key(g: PIDGains) -> tuple[float, float, float] | None:
    return (g.notch_fn, g.notch_zeta_zero, g.notch_zeta_pole) if g.notch_fn > 0 else None


class PID(BaseController):
    """PID with back-calculation anti-windup and filtered derivative on the measurement."""

    name = "pid"

    @classmethod
    def create(cls, model, dt, limits, gains=None, initial="model"):
        """See :meth:`hyst_control.base.BaseController.create` (no model: feedback only)."""
        return cls(dt, gains or PIDGains(), limits)

    def __init__(self, dt: float, gains: PIDGains = PIDGains(), limits: CommandLimits | None = None) -> None:
        super().__init__(dt, limits)
        self.gains = gains
        self._notch = gains.notch(dt)  # ConfigError for a notch the sample rate cannot hold
        self._i = 0.0
        self._d = 0.0
        self._raw = math.nan
        self._pre = math.nan  # the sum before the notch
        self._e = 0.0

    def set_gains(self, gains: PIDGains) -> None:
        """Swap gains bumplessly: the integrator absorbs the change of the proportional term; a changed notch starts
        in steady state at the last output, the integrator absorbing what its old state held back."""
        notch = gains.notch(self.dt)
        if math.isfinite(self._e):
            self._i += (self.gains.kp - gains.kp) * self._e
        if _notch_key(gains) != _notch_key(self.gains):
            if math.isfinite(self._raw) and math.isfinite(self._pre):
                self._i += self._raw - self._pre  # the sum now equals the output in force
                self._pre = self._raw
                if notch is not None:
                    notch.reset(self._raw)
            self._notch = notch
        self.gains = gains

    def _on_reset(self, y0: float, u0: float, r0: float) -> None:
        self._e = r0 - y0
        self._d = 0.0
        self._i = u0 - self.gains.kp * self._e  # first output = u0: bumpless
        self._raw = self._pre = u0
        if self._notch is not None:
            self._notch.reset(u0)

    def _law(self, r_k: float, y: float) -> float:
        g, dt = self.gains, self.dt
        e = r_k - y
        a = dt / (g.t_filter + dt)
        self._d += a * (-g.kd * (y - self._y_prev) / dt - self._d)
        self._i += g.ki * dt * e
        self._e = e
        self._pre = g.kp * e + self._i + self._d
        self._raw = self._notch.step(self._pre) if self._notch is not None else self._pre
        return self._raw

    def _commit(self, u: float) -> None:
        # Back-calculation: bleed the integrator by the part of the output the limiter removed.
        if u != self._raw:
            self._i += (u - self._raw) * min(1.0, self.dt / self.gains.t_track)

    def state(self) -> dict[str, float]:
        s = super().state()
        s.update(p=self.gains.kp * self._e, i=self._i, d=self._d)
        return s


class OpenLoop(ModelBased):
    """Inverse-model feedforward: u_k such that the model's predicted output equals r_k; no feedback.

    Bumpless start: the model state starts at the measurement, and whatever difference remains between the
    course of the command in force (last command plus its last increment, see :func:`hyst_control.base.hand_over`)
    and the first feedforward command is faded out with time constant ``bump_tau`` (s); the model is advanced
    with the pure feedforward part.
    """

    name = "open_loop"

    @classmethod
    def create(cls, model, dt, limits, gains=None, initial="model"):
        """See :meth:`hyst_control.base.BaseController.create` (no gains)."""
        return cls(model, dt, limits)

    def __init__(self, model: MBWParams, dt: float, limits: CommandLimits | None = None,
                 zeta0: float = 1e-3, exact_rate: bool = True, bump_tau: float = 0.02) -> None:
        super().__init__(model, dt, limits)
        if not zeta0 > 0:
            raise ConfigError("zeta0 must be positive")
        self.zeta0 = zeta0
        self.exact_rate = exact_rate
        if not bump_tau > 0:
            raise ConfigError("bump_tau must be positive")
        self._fade = math.exp(-dt / bump_tau)
        self._ym_state = 0.0
        self._ym_applied = 0.0  # the model driven by the command applied (bump and limiter included)
        self._ua = 0.0
        self._nu = 0.0
        self._uff = 0.0
        self._bump = math.nan

    @property
    def applied_shift(self) -> float:
        """What the model says the stage does beyond what the feedforward assumed (m): the response to the faded
        bump and to what the limiter took off. Zero once both are over and the model's memory has forgotten them.

        The law advances its model with the feedforward alone (so the bump fades instead of being cancelled);
        effects with slow memory (creep) must follow the stage's actual course, which this shift supplies
        (:class:`hyst_control.compensation.Compensated`)."""
        return (self._ym_applied - self._ym_state) * self._ys

    def sync_applied(self, u_applied: float) -> None:
        """Open loop follows its own model, not the measured side: nothing to synchronise."""

    def _rescale(self, old: MBWParams, new: MBWParams) -> None:
        """The model's predicted position, in the new model units (the same metres)."""
        self._ym_state = self._pos(self._ym_state, old, new)
        self._ym_applied = self._pos(self._ym_applied, old, new)

    def _on_reset(self, y0: float, u0: float, r0: float) -> None:
        self._ym_state = self._ym_applied = self._ym(y0)
        self._uff = self._ua = u0
        self._bump = math.nan  # measured at the first step

    def _law(self, r_k: float, y: float) -> float:
        ys, us, p = self._ys, self._us, self._p
        r_m = (r_k - self._off) / ys
        r_u = abs(r_k - self._r_prev) / ys
        y_r = r_m - p[6] * self._ym_state
        nu = invert_nu(p, self._ym_state, y_r, self._uff / us, r_u, self.exact_rate, self.zeta0)
        self._nu = nu
        u_ff = (p[7] * self._uff / us + nu) * us
        if self._bump != self._bump:
            # The bump is the departure from the command's course in force (u_{k−1} plus its last increment),
            # not from u_{k−1}: holding u_{k−1} for a sample on a moving reference (10 Hz sine: ≈ 1.7 V per
            # sample) and fading it out was itself the bump (pid → open_loop: +250 nm for ≈ 70 ms).
            # ... and from the feedforward the stage can get: handed over while saturated (r beyond the stroke),
            # a bump against an unreachable feedforward was the saturation itself, still −12 V 50 ms later
            lim = self.limits
            self._bump = self._u_prev + self._du - min(max(u_ff, lim.v_min), lim.v_max)
        else:
            self._bump *= self._fade
        return u_ff + self._bump

    def _commit(self, u: float) -> None:
        # what the feedforward actually got through the limiter, within the range: handed over while saturated
        # (150 V with a -45 V bump) the model was advanced with 195 V and predicted beyond the stroke (790 nm)
        lim = self.limits
        u_ff = min(max(u - self._bump, lim.v_min), lim.v_max)
        self._ym_state = mbw_step(self._p, self._ym_state, u_ff / self._us, self._uff / self._us)
        self._uff = u_ff
        ya = mbw_step(self._p, self._ym_applied, u / self._us, self._ua / self._us)
        # a diverged prediction must not poison the shift; it falls back to the feedforward's course
        self._ym_applied = ya if math.isfinite(ya) else self._ym_state
        self._ua = u

    def state(self) -> dict[str, float]:
        s = super().state()
        s.update(nu=self._nu * self._us, prediction=self._ym_state * self._ys + self._off)
        return s
