"""Per-sample forms of effects, for controllers: the identified model, used where it matters most.

A controller built on the base hysteresis model (DPPC, DMRAC, the open-loop inverse) tracks the base model's
output. When the user has identified effects on top of the base (``model.effects``), the controller can still use
them: each effect that supports it returns an :class:`OnlineEffect` from :meth:`Effect.online`, which maps

* the **measurement** back through the effect: the value the inner structure produced (the base model's output
  for the innermost effect), advancing the effect's own state with the sample (creep lags, delay buffers);
* the **target**: the inner value that makes the measured output equal the reference (the effect inverted on the
  reference), without advancing any state;
* the **reachable range** of the measured output (a saturating stage cannot be asked beyond its limit);
* an **observation** hook: the base-level value the measurement became, for an effect that must be estimated from
  the sensor rather than inverted (drift: an input-independent offset, tracked by a disturbance observer).

The controller then runs its law on the inner values, so a creep, a bent loop or a saturating stroke is
compensated by inversion, and a transport delay by a Smith predictor (the inner value is the measurement plus the
base model's undelayed minus delayed prediction) with the reference taken ``preview`` seconds ahead.

Timing: ``measure(y, u)`` gets the newest measured sample and the input that was applied for it; ``target(r, u)``
the reference for the next sample and the newest applied input as a stand-in for the one being computed.
Everything is SI (m, V).
"""
from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from ..core import MBWParams
from ..core.mbw import mbw_rest_state, mbw_step

__all__ = ["OnlineEffect", "Stepper", "MBWStepper"]


class OnlineEffect:
    """Per-sample inverse of one effect (identity by default); see the module docstring."""

    #: Effect name (for reports).
    name: str = "effect"
    #: Seconds of reference preview the compensation needs (a delay's τ); 0 for static and causal effects.
    preview: float = 0.0
    #: True for an effect estimated from the sensor (an observer): the open-loop inverse, which reads no
    #: sensor, cannot use it.
    needs_sensor: bool = False

    def reset(self, y: float, u: float) -> None:
        """Start at rest: measured output ``y`` (m) held under input ``u`` (V)."""

    def measure(self, y: float, u: float) -> float:
        """Measured output ``y`` (m) with applied input ``u`` (V) → the inner structure's output; advances state."""
        return y

    def target(self, r: float, u: float) -> float:
        """Desired measured output ``r`` (m) → inner output that produces it; no state change."""
        return r

    def bounds(self) -> tuple[float, float]:
        """Reachable range of this effect's output (m); ``(-inf, inf)`` when unbounded."""
        return (-math.inf, math.inf)

    #: True when :meth:`forward` predicts this effect's output from the inner structure's (static maps, the
    #: Smith predictors).
    predictive: bool = False
    #: True when :meth:`measure` is a Smith predictor (delay, series resonance): the measurement minus the model's
    #: prediction through this effect plus the prediction without it. With a compensation's own base model, such
    #: effects and the predictive ones inside them are predicted as one chain (each alone compares the
    #: measurement with its own effect on the bare base, wrong by the other effects' share: DPPC with a delay and
    #: a mode saturated on its own model).
    smith: bool = False

    def start(self, x: float, u: float) -> None:
        """Predictive effects: rest with the inner structure's predicted output ``x`` (m) under input ``u`` (V)."""

    def forward(self, z: float, w: float, u: float, first: bool) -> tuple[float, float]:
        """Predictive effects: advance one sample of the model's prediction through this effect.

        ``z`` is the inner structure's predicted *measurement* for the newest applied input ``u``, ``w`` the same
        without any delay (the prediction ``preview`` ahead: delays commute with the other time-invariant stages);
        returns both through this effect. :meth:`target` reads the state ``w`` drives (it aims ``preview`` ahead).
        ``first``: this effect is innermost (``z`` = ``w`` = the base model's prediction).
        """
        raise NotImplementedError(f"{self.name} has no forward prediction")

    def mismatch(self, e: float) -> None:
        """Smith predictors: the newest reading minus the model's prediction at this effect's output (m), given
        before :meth:`observe`; an effect whose inverse's state follows the measured mismatch keeps it."""

    def observe(self, x: float, u: float) -> None:
        """After a measurement went through every effect: ``x`` (m) is the base-level value the law will see.

        An observer (drift) compares it with its own base-model prediction for input ``u``; the others ignore
        it. Not called when the law runs on its own aim instead of the sensor (open loop).
        """


class Stepper(Protocol):
    """The base model run sample by sample (SI): what a Smith predictor needs."""

    def reset(self, u0: float) -> float:
        """Rest at input ``u0`` (V); returns the output (m)."""

    def step(self, u: float) -> float:
        """Apply ``u`` (V) for one sample; returns the output (m)."""


class MBWStepper:
    """The one MBW recursion (3.21) per sample, in SI through the model's scales.

    Parameters
    ----------
    model : MBWParams
        Base model (thesis ν convention).
    """

    def __init__(self, model: MBWParams) -> None:
        self._p = np.ascontiguousarray(model.vector)
        self._us, self._ys, self._off = model.u_scale, model.y_scale, model.offset
        self._x = 0.0
        self._u = 0.0

    def reset(self, u0: float) -> float:
        um = u0 / self._us
        self._u = um
        self._x = float(mbw_rest_state(self._p, um))
        return self._ys * self._x + self._off

    def step(self, u: float) -> float:
        um = u / self._us
        x = float(mbw_step(self._p, self._x, um, self._u))
        if math.isfinite(x):  # a model pushed outside its range must not poison the predictor
            self._x = x
        self._u = um
        return self._ys * self._x + self._off
