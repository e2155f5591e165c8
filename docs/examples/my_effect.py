"""An effect of your own: mains hum picked up by the displacement sensor.

Use it anywhere a built-in effect works::

    hyst diagnose bags/x --effect-module docs/examples/my_effect.py          # tested as a candidate
    hyst fit bags/x --effects creep,hum --effect-module docs/examples/my_effect.py --out p.yaml

The API (``hyst_model.effects.Effect``, see ``hyst_model/effects/base.py``):

* class attributes ``name`` (registry key; parameters are stored as ``hum.a`` ...), ``summary``, ``physics``,
  ``kind``: ``"output"`` (implement :meth:`output`), ``"input"`` (implement :meth:`input`), ``"wrap"`` or
  ``"base"`` (implement :meth:`apply`, which receives the inner model as a callable ``inner(t, u)``);
* :meth:`params`: local parameters with SI units and bounds; their defaults must make the effect the identity;
* :meth:`start` (optional): initial values from the data and the base model's residual;
* :meth:`signature`: ``(score in [0, 1], one sentence of evidence)`` — how much the residual looks like it.

Fixed settings come in through the constructor's ``config`` (``self.dt``, ``self.u_scale``, ``self.y_scale``);
keys you return from :meth:`config` are stored in params files as ``hum.<key>`` and given back to you.
"""
from __future__ import annotations

import numpy as np

from hyst_model.effects import Effect
from hyst_model.model import Param


class Hum(Effect):
    """A sinusoid at the mains frequency added to the measurement (sensor cable pick-up)."""

    name = "hum"
    summary = "mains hum on the sensor signal (50/60 Hz pick-up)"
    physics = ("An unshielded sensor cable picks up the mains field: the reading carries a small sinusoid at "
               "the mains frequency whatever the stage does.")
    kind = "output"

    def __init__(self, config=None):
        super().__init__(config)
        self.freq = float(self._config.get("hum.freq", 50.0))  # Hz; set 60 for 60 Hz mains

    def params(self):
        b = 10.0 * self.y_scale
        return (Param("a", 0.0, -b, b, "m", "cosine amplitude at the mains frequency"),
                Param("b", 0.0, -b, b, "m", "sine amplitude at the mains frequency"))

    def config(self):
        return {"freq": self.freq}

    def _basis(self, t):
        w = 2 * np.pi * self.freq * np.asarray(t, float)
        return np.cos(w), np.sin(w)

    def output(self, theta, t, u, y):
        c, s = self._basis(t)
        return y + theta[0] * c + theta[1] * s

    def start(self, t, u, y, residual):
        c, s = self._basis(t)
        return {"a": 2 * float(np.mean(residual * c)), "b": 2 * float(np.mean(residual * s))}

    def signature(self, t, u, residual, dt):
        if self.freq >= 0.5 / dt:
            return 0.0, f"the sample rate is too low to see {self.freq:g} Hz"
        c, s = self._basis(t)
        amp = 2 * np.hypot(np.mean(residual * c), np.mean(residual * s))
        rms = float(np.sqrt(np.mean(residual ** 2))) or 1e-300
        share = float(np.clip((amp / np.sqrt(2)) / rms, 0.0, 1.0))
        return share, f"a {self.freq:g} Hz line of {amp * 1e9:.3g} nm carries {share:.0%} of the residual RMS"
