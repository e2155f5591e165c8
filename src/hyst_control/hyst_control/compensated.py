"""A control law with the identified effects inverted around it (:mod:`hyst_control.compensation` plans them)."""
from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

from .base import BaseController
from .errors import ConfigError

if TYPE_CHECKING:
    from .compensation import Compensation

__all__ = ["Compensated", "wrap"]


class Compensated:
    """A controller running on the base model's output, with the effects inverted around it.

    Same protocol as :class:`~hyst_control.base.BaseController` (SI in and out, ``reset``/``step``/``state``);
    everything else (limits, gains, ``set_model``, ``sync_applied``, ...) is the inner controller's.

    Parameters
    ----------
    inner : BaseController
        The law (its measurement and reference become base-model outputs).
    comp : Compensation
    """

    def __init__(self, inner: BaseController, comp: Compensation) -> None:
        self.inner = inner
        self.comp = comp
        self.name = inner.name
        # Open loop never reads the sensor: its effect states follow what it aimed at (an internal model).
        self._internal = inner.name == "open_loop"
        comp.internal = self._internal  # its effect states then follow the model's prediction where they can
        self._r_prev = math.nan
        self._r_aim = math.nan
        self._y_prev = math.nan
        # References passed, newest first: with a preview of d samples the newest measurement answers the one
        # passed d + 1 samples ago (the published error compares with that, not with a future reference).
        self._n_passed = int(round(comp.preview / inner.dt)) + 1
        self._passed: deque[float] = deque(maxlen=self._n_passed)

    def __getattr__(self, item):  # dt, gains, set_model, sync_applied, notice_gap, ...
        return getattr(self.inner, item)

    @property
    def limits(self):
        return self.inner.limits

    @limits.setter
    def limits(self, value) -> None:  # the node swaps limits on a parameter change: they belong to the law
        self.inner.limits = value

    @property
    def preview(self) -> float:
        return self.comp.preview

    @property
    def last_reference(self) -> float:
        return self._r_prev

    def reset(self, y0: float, u0: float, r0: float | None = None) -> None:
        if not math.isfinite(y0):
            raise ConfigError("reset needs a finite measurement y0")
        r0 = y0 if r0 is None or not math.isfinite(r0) else float(r0)
        x0 = self.comp.reset(float(y0), float(u0))
        self.inner.reset(x0, u0, self.comp.target(r0, float(u0)))
        self._r_prev = self._r_aim = r0
        self._y_prev = float(y0)
        self._passed.clear()
        self._passed.extend([r0] * self._n_passed)

    def step(self, r_k: float, y_k: float) -> float:
        inner = self.inner
        if inner.last_command != inner.last_command:  # never reset: start from the safe output, as the laws do
            self.reset(y_k if math.isfinite(y_k) else 0.0, inner.limits.v_safe, r_k)
        u_prev = inner.last_command
        if not math.isfinite(r_k):
            r_k = self._r_prev
        # The reference this measurement answers (passed preview + 1 samples ago): open loop's stand-in for y_k.
        # (Taking the aim of the sample before lagged the effect states one sample behind the model: the
        # open-loop inverse with creep was 8 nm off its own model on a 10 Hz sine.)
        aim = self._passed[-1]
        if math.isfinite(y_k):
            # open loop: the aim, moved by what the model says the applied command did beyond it (the start's
            # faded bump, a limited command), so slow effect memory (creep lags) follows the stage's course;
            # where every effect predicts, the compensation takes the model's prediction instead (exact)
            seen = aim + getattr(inner, "applied_shift", 0.0) if self._internal and math.isfinite(aim) else y_k
            x = self.comp.measure(seen, u_prev, sensor=not self._internal)
        else:
            x = y_k  # the law counts and holds on a bad sample (its own model skips it as well)
        u = inner.step(self.comp.target(r_k, u_prev), x)
        self._r_aim = aim
        self._passed.appendleft(r_k)
        self._r_prev, self._y_prev = r_k, y_k
        return u

    def state(self) -> dict[str, float]:
        s = dict(self.inner.state())
        s["error"] = self._y_prev - self._r_aim  # the published error is on the measured output, in m
        s["limited"] = float(self.comp.limited)
        drift = self.comp.drift()
        if drift is not None:
            s["drift"] = drift[0]
            if not drift[1]:  # a drifting sensor: what the stage's position is off (the reading minus the offset)
                s["position_error"] = self._y_prev - drift[0] - self._r_aim
        return s


def wrap(controller: BaseController, comp: Compensation | None) -> BaseController | Compensated:
    """``controller`` with ``comp`` around it, or unchanged when nothing is compensated."""
    return Compensated(controller, comp) if comp is not None and comp.used else controller
