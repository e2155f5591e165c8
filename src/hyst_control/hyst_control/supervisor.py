"""Oscillation watch: a loop that rings on a resonance its model does not know is derated, not left to ring.

The stability check (:mod:`hyst_control.stability`) judges the gains against an *identified* resonance. A stage
mode the identification did not see (a mode near the Nyquist frequency, one masked by another effect in the
diagnosis, a load change since) can still make a default-gain loop unstable: the command then swings between its
limits at the mode's frequency. Commercial piezo controllers watch for this and back off; so does hyst:

* :class:`OscillationMonitor` flags a *sustained* fast swing of the command: in each window of ``window``
  seconds, the share of samples where a command increment larger than ``level`` of the voltage range reverses
  the sign of the previous such increment, at most :data:`GAP` samples earlier, for ``windows`` windows in a row.
  A swing at f reverses about 2·f·dt of the samples (0.52 at 520 Hz, 0.3 at 300 Hz at 2 kHz), and one clipped at
  the limits reverses between its flat stretches just as often; tracking a 100 Hz sine reverses only every 10
  samples (beyond GAP), a step once, and sensor noise moves the command by far less than ``level`` — so
  ``share`` = 0.25 flags modes above about fs/8 (250 Hz at 2 kHz) and nothing a reference asks for. A ringing
  loop that stays below its limits (a bounded limit cycle of a few volts) is caught too. The measured output must
  swing the same way (increments above 0.1 % of the stage's range, :func:`output_span`): a command may swing on
  purpose — an identified resonance inverted on the reference excites the mode's frequency to cancel it, and was
  taken for an oscillation (derated χ 0.93 → 0.98: 40 nm instead of 4 nm on a 30 Hz sine) — and then the output
  stays smooth, while a ringing loop moves the stage by micrometres. Slower instabilities (below fs/8) are not
  caught.
* :class:`Supervised` wraps a law: on a flagged oscillation it rebuilds the law with derated gains (the
  derating direction of :func:`hyst_control.stability.derate`: DPPC χ and DMRAC a_m towards 0.995, PID gains
  down) at the next level of :data:`LEVELS`, hands over bumplessly and records the event (the node warns on
  ``/diagnostics``); past the last level it falls back to the open-loop inverse, which has no loop to ring.

Nothing here knows the resonance: it reacts to what the loop does. Thresholds are fractions of the voltage range
and of the sample rate, not tuned to a stage.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from .base import hand_over
from .errors import ControlError
from .stability import _DERATED, _candidate

__all__ = ["OscillationMonitor", "Supervised", "LEVELS", "output_span"]

#: Derating steps tried in turn, per law (t of :func:`hyst_control.stability._candidate`: 0 = as configured,
#: 1 = χ, a_m at 0.995, PID gains / 10⁴): DPPC χ 0.1 → 0.55, 0.82, 0.995; PID gains / 3.2, 10, 100.
LEVELS = {"dppc": (0.5, 0.8, 1.0), "dmrac": (0.5, 0.8, 1.0), "pid": (0.125, 0.25, 0.5)}
#: A reversal counts when the previous large increment is at most this many samples old: swings faster than
#: fs/(2·GAP) (250 Hz at 2 kHz), clipped or not.
GAP = 4


def output_span(model, v_range: tuple[float, float]) -> float:
    """The model's output range between the command limits at rest (m): the scale of an output swing."""
    from hyst_model.effects.online import MBWStepper

    m = MBWStepper(model)
    return abs(m.reset(float(v_range[1])) - m.reset(float(v_range[0])))


class _Reversals:
    """Counts reversals of a signal's large increments (> ``thr``) within :data:`GAP` samples of the last one."""

    def __init__(self, thr: float) -> None:
        self.thr = thr
        self.reset()

    def reset(self) -> None:
        self._x1 = math.nan
        self._sign = 0.0   # sign of the last increment larger than thr
        self._since = 0    # samples since it
        self.count = 0

    def update(self, x: float) -> None:
        d = x - self._x1
        self._since += 1
        if math.isfinite(d) and abs(d) > self.thr:
            sign = math.copysign(1.0, d)
            # a clipped swing reverses between flat stretches at its limits: the reversal is between the last
            # large increments, not adjacent samples
            if sign != self._sign and self._sign != 0.0 and self._since <= GAP:
                self.count += 1
            self._sign, self._since = sign, 0
        if math.isfinite(x):
            self._x1 = x


class OscillationMonitor:
    """Flags a sustained fast swing of the command and of the measured output (see the module docstring).

    Parameters
    ----------
    dt : float
        Sample period (s).
    v_range : (float, float)
        Command limits (V); ``level`` is a fraction of their span.
    y_span : float, optional
        The output's range over ``v_range`` (m, from the model); with it the measured output must swing too
        (by ``level_y`` of it): a command that swings on purpose — a resonance inverted on the reference excites
        the mode's frequency to cancel it — leaves the output smooth. Without it only the command is watched.
    level, level_y, window, share, windows
        Increment thresholds (fractions of the spans), window length (s), share of samples with a reversal for
        a window to count, and windows in a row to flag.
    """

    def __init__(self, dt: float, v_range: tuple[float, float], y_span: float | None = None,
                 level: float = 0.005, level_y: float = 0.001, window: float = 0.02, share: float = 0.25,
                 windows: int = 3) -> None:
        span = float(v_range[1]) - float(v_range[0])
        if not (dt > 0 and span > 0 and level > 0 and level_y > 0 and window > 0 and 0 < share <= 1
                and windows >= 1):
            raise ValueError("OscillationMonitor needs dt > 0, a non-empty v_range, levels and window > 0, "
                             "0 < share <= 1 and windows >= 1")
        self._cmd = _Reversals(level * span)
        self._out = _Reversals(level_y * abs(y_span)) if y_span and math.isfinite(y_span) else None
        self._n = max(8, int(round(window / dt)))
        self._need = share * self._n
        self._windows = int(windows)
        self.reset()

    def reset(self) -> None:
        self._cmd.reset()
        if self._out is not None:
            self._out.reset()
        self._i = self._run = 0

    def update(self, u: float, y: float = math.nan) -> bool:
        """Take the newest command and measurement; True when an oscillation is confirmed (then it starts afresh)."""
        self._cmd.update(u)
        if self._out is not None:
            self._out.update(y)
        self._i += 1
        if self._i < self._n:
            return False
        hit = self._cmd.count >= self._need and (self._out is None or self._out.count >= self._need)
        self._run = self._run + 1 if hit else 0
        self._cmd.count = self._i = 0
        if self._out is not None:
            self._out.count = 0
        if self._run >= self._windows:
            self._run = 0
            return True
        return False


class Supervised:
    """A law whose commands are watched; on an oscillation it is rebuilt derated (same protocol as the law).

    Parameters
    ----------
    law : controller
        The running law (a :class:`~hyst_control.base.BaseController` or a compensated one).
    algorithm : str
        Its name in :data:`hyst_control.controllers.CONTROLLERS`.
    gains : gains dataclass or None
        The gains it was built with (the derating starts from them).
    rebuild : callable
        ``rebuild(algorithm, gains) -> controller``: a fresh law with the same model, limits and compensation.
    dt : float
        Sample period (s).
    v_range : (float, float)
        Command limits (V).
    act : bool
        False: only record the oscillation (``stability.policy: warn``), keep the gains.
    y_span : float, optional
        The stage's output range over ``v_range`` (m): the measured output must swing too (see
        :class:`OscillationMonitor`).
    """

    def __init__(self, law, algorithm: str, gains, rebuild: Callable[[str, Any], Any], dt: float,
                 v_range: tuple[float, float], act: bool = True, y_span: float | None = None) -> None:
        self.law = law
        self.algorithm = algorithm
        self.configured = gains
        self._rebuild = rebuild
        self._act = act
        self.monitor = OscillationMonitor(dt, v_range, y_span)
        self.level = 0
        #: What happened, one sentence per oscillation (for logs and /diagnostics).
        self.events: list[str] = []

    def __getattr__(self, item):  # name, dt, gains, preview, set_model, sync_applied, last_command, ...
        return getattr(self.law, item)

    @property
    def inner(self):
        """The bare law (inside any compensation): what owns the command memory."""
        return getattr(self.law, "inner", self.law)

    @property
    def limits(self):
        return self.law.limits

    @limits.setter
    def limits(self, value) -> None:
        self.law.limits = value

    def set_gains(self, gains) -> None:
        """New configured gains (a parameter change): they run as set, and a derating starts again from them."""
        self.configured = gains
        self.level = 0
        if hasattr(self.law, "set_gains"):
            self.law.set_gains(gains)

    def reset(self, y0: float, u0: float, r0: float | None = None) -> None:
        self.monitor.reset()
        self.law.reset(y0, u0, r0)

    def step(self, r_k: float, y_k: float) -> float:
        u = self.law.step(r_k, y_k)
        if self.monitor.update(u, y_k):
            self._escalate(r_k, y_k)
        return u

    def state(self) -> dict[str, float]:
        s = dict(self.law.state())
        s["derated"] = float(self.level)
        return s

    def _escalate(self, r_k: float, y_k: float) -> None:
        where = f"{self.algorithm}: the command oscillates (a resonance the model does not know?)"
        if not self._act:
            self.events.append(f"{where}; gains kept (stability.policy = warn)")
            return
        self.level += 1
        steps = LEVELS.get(self.algorithm, ())
        if self.algorithm in _DERATED and self.configured is not None and self.level <= len(steps):
            gains = _candidate(self.algorithm, self.configured, steps[self.level - 1])
            changed = ", ".join(f"{n} {float(getattr(self.configured, n)):.4g} -> {float(getattr(gains, n)):.4g}"
                                for n in _DERATED[self.algorithm]
                                if getattr(gains, n) != getattr(self.configured, n))
            new = self._rebuild(self.algorithm, gains)
            msg = f"{where}; derated (level {self.level} of {len(steps)}: {changed})"
        elif self.algorithm != "open_loop":
            try:
                new = self._rebuild("open_loop", None)
            except ControlError as err:  # a model that runs away open loop is no fallback (controller_settings)
                self.events.append(f"{where}; still oscillating at the last derating level, and the open-loop "
                                   f"inverse is no fallback: {err}")
                return
            self.algorithm = "open_loop"
            msg = f"{where}; still oscillating at the last derating level: fell back to the open-loop inverse"
        else:
            self.events.append(f"{where}; no loop left to derate")
            return
        y = y_k if math.isfinite(y_k) else self.law.last_reference
        self.law = hand_over(new, self.law, y, r_k)
        self.monitor.reset()
        self.events.append(msg)
