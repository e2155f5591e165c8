"""Reference generators (pure functions of time, SI metres), the thesis's test trajectories on the PEA stroke.

The thesis gives frequencies but no amplitudes for its PEA tests (ch. 4.3.2) and defines DMRAC Case 3 in µm on
the GMA (ch. 5.3.2). hyst scales every trajectory to the 30 µm PEA stroke and documents the choice:

==============  ==================================================================================================
``step``        5 µm → 20 µm at t = 0.1 s
``ramp``        5 µm, then 40 µm/s from t = 0.1 s for 0.375 s (to 20 µm), then held
``step+ramp``   5 µm → 12.5 µm step at t = 0.1 s, then a 7.5 µm ramp over 0.375 s (to 20 µm)
``sine:F``      15 µm + 10 µm·sin(2πFt) (5–25 µm, two thirds of the stroke); ``sine:F:A`` sets A in µm
``c1``          15 µm + 4 µm·sin(2π5t) + 3 µm·sin(2π15t) + 2 µm·sin(2π40t) (thesis C1: 5 + 15 + 40 Hz)
``c2``          15 µm + 10 µm·sin(φ(t)), frequency sweeping linearly 1 → 20 Hz over 2 s and back (thesis C2)
``c3``          15 µm + 6 µm·sin(2π5t) + 4 µm·cos(2π20t) − 4 µm (thesis C3: two sines; starts at 15 µm)
``case3``       15 µm + 2·(3 µm·sin(2π·3.5t) + 1.5 µm·cos(2π·1.5t)) − 3 µm (DMRAC Case 3, ×2 so its 4.5 µm peak
                becomes 9 µm like the other references' ≈ 10 µm; the constant makes r(0) = 15 µm)
==============  ==================================================================================================

On another stage, :func:`parse_reference` ``stroke=(lo, hi)`` places the same shapes on that stroke: offsets and
default amplitudes scale with it (``sine:10`` on a ±19 µm stage swings ±12.7 µm about 0 — the same sixths of the
stroke), while numbers given in a spec (``sine:F:A_um``, ``constant:LEVEL_um``) stay the absolute µm they say.

Every reference provides its analytic rate (published as ``velocity[0]``), which lets the controller node
extrapolate to the sample time its command will act at.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np

from .errors import ReferenceError_

__all__ = ["Reference", "parse_reference", "SHAPES", "TABLE_REFERENCES", "PEA_STROKE"]

UM = 1e-6
#: The stroke (m) the documented defaults are placed on: the PEA's 30 µm from rest at 0 V.
PEA_STROKE = (0.0, 30 * UM)

#: Shapes understood by :func:`parse_reference` / the reference node's ``shape`` parameter.
SHAPES = ("step", "ramp", "step+ramp", "sine", "c1", "c2", "c3", "case3", "constant")

#: The references of thesis Tables 4.3/4.4/5.2 in table order.
TABLE_REFERENCES = ("step", "ramp", "step+ramp", "sine:1", "sine:5", "sine:10", "sine:20", "sine:30",
                    "c1", "c2", "c3")


@dataclass(frozen=True)
class Reference:
    """A reference trajectory r(t) (m) with its rate (m/s).

    Attributes
    ----------
    shape : str
        One of :data:`SHAPES`.
    amplitude : float
        Main amplitude (m); meaning per shape (step height, sine amplitude, scale of composite shapes as a
        factor of their documented default).
    frequency : float
        Hz (sine; the sweep's upper frequency for c2).
    offset : float
        Level the trajectory starts from or oscillates about (m).
    t0 : float
        Start time of steps and ramps (s).
    """

    shape: str = "sine"
    amplitude: float = 10 * UM
    frequency: float = 10.0
    offset: float = 15 * UM
    t0: float = 0.1
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ReferenceError_(f"unknown reference shape {self.shape!r}; choose one of {', '.join(SHAPES)}")
        for name in ("amplitude", "frequency", "offset", "t0"):
            if not math.isfinite(getattr(self, name)):
                raise ReferenceError_(f"reference {name} must be finite")
        if self.frequency < 0:
            raise ReferenceError_("reference frequency must be >= 0")

    def extent(self, seconds: float = 8.0) -> tuple[float, float]:
        """Lowest and highest r(t) (m) over the first ``seconds`` (every shape repeats or settles within 4 s),
        sampled finely enough for its fastest component."""
        n = int(min(max(200.0 * seconds * max(self.frequency, 40.0), 2000.0), 2e6))
        r = self._eval(np.linspace(0.0, seconds, n))[0]
        return float(np.min(r)), float(np.max(r))

    def __call__(self, t):
        """r(t) in metres (scalar or array)."""
        return self.sample(t)[0]

    def sample(self, t):
        """(r(t), ṙ(t)) in m and m/s; ``t`` scalar or array (s)."""
        t = np.asarray(t, dtype=np.float64)
        r, v = self._eval(t)
        if r.ndim == 0:
            return float(r), float(v)
        return r, v

    def _eval(self, t: np.ndarray):
        s, a, f, o, t0 = self.shape, self.amplitude, self.frequency, self.offset, self.t0
        two_pi = 2.0 * np.pi
        zero = np.zeros_like(t)
        if s == "constant":
            return o + zero, zero
        if s == "step":
            return o + a * (t >= t0), zero
        if s in ("ramp", "step+ramp"):
            T = 0.375
            jump = a / 2 if s == "step+ramp" else 0.0
            x = np.clip((t - t0) / T, 0.0, 1.0)
            inside = (t >= t0) & (t < t0 + T)
            return o + jump * (t >= t0) + (a - jump) * x, np.where(inside, (a - jump) / T, 0.0)
        if s == "sine":
            w = two_pi * f
            return o + a * np.sin(w * t), a * w * np.cos(w * t)
        k = a / (10 * UM)  # composite shapes scale with amplitude relative to the 10 µm default
        if s == "c1":
            r = zero.copy()
            v = zero.copy()
            for amp, fr in ((4.0, 5.0), (3.0, 15.0), (2.0, 40.0)):
                w = two_pi * fr
                r += amp * UM * k * np.sin(w * t)
                v += amp * UM * k * w * np.cos(w * t)
            return o + r, v
        if s == "c2":
            f0, f1, T = 1.0, (f if f > 1.0 else 20.0), 2.0
            tm = np.mod(t, 2 * T)  # up-sweep, then the mirror image: frequency is continuous
            up = tm < T
            # phase of a linear sweep f0 → f1 over T, then f1 → f0 over T
            ph_up = two_pi * (f0 * tm + 0.5 * (f1 - f0) / T * tm ** 2)
            ph_T = two_pi * (f0 * T + 0.5 * (f1 - f0) * T)
            td = tm - T
            ph_dn = ph_T + two_pi * (f1 * td - 0.5 * (f1 - f0) / T * td ** 2)
            cycles = np.floor(t / (2 * T))
            ph = np.where(up, ph_up, ph_dn) + cycles * 2 * ph_T
            fi = np.where(up, f0 + (f1 - f0) * tm / T, f1 - (f1 - f0) * td / T)
            return o + a * np.sin(ph), a * two_pi * fi * np.cos(ph)
        if s == "c3":
            w1, w2 = two_pi * 5.0, two_pi * 20.0
            r = 6 * UM * k * np.sin(w1 * t) + 4 * UM * k * (np.cos(w2 * t) - 1.0)
            v = 6 * UM * k * w1 * np.cos(w1 * t) - 4 * UM * k * w2 * np.sin(w2 * t)
            return o + r, v
        if s == "case3":
            w1, w2 = two_pi * 3.5, two_pi * 1.5
            g = 2.0 * k
            r = g * (3 * UM * np.sin(w1 * t) + 1.5 * UM * (np.cos(w2 * t) - 1.0))
            v = g * (3 * UM * w1 * np.cos(w1 * t) - 1.5 * UM * w2 * np.sin(w2 * t))
            return o + r, v
        raise ReferenceError_(f"unhandled shape {s!r}")  # pragma: no cover


class _Shape(TypedDict, total=False):
    """A shape's defaults: keyword arguments of :class:`Reference`."""

    amplitude: float
    frequency: float
    offset: float


_DEFAULTS: dict[str, _Shape] = {
    "step": _Shape(amplitude=15 * UM, offset=5 * UM),
    "ramp": _Shape(amplitude=15 * UM, offset=5 * UM),
    "step+ramp": _Shape(amplitude=15 * UM, offset=5 * UM),
    "stepramp": _Shape(amplitude=15 * UM, offset=5 * UM),
    "sine": _Shape(amplitude=10 * UM, offset=15 * UM),
    "c1": _Shape(amplitude=10 * UM, offset=15 * UM),
    "c2": _Shape(amplitude=10 * UM, offset=15 * UM, frequency=20.0),
    "c3": _Shape(amplitude=10 * UM, offset=15 * UM),
    "case3": _Shape(amplitude=10 * UM, offset=15 * UM),
    "constant": _Shape(amplitude=0.0, offset=15 * UM),
}


def parse_reference(spec: str, stroke: tuple[float, float] | None = None) -> Reference:
    """Build a reference from a short spec: ``step``, ``ramp``, ``step+ramp``, ``sine:F[:A_um]``, ``c1``,
    ``c2``, ``c3``, ``case3``, ``constant[:LEVEL_um]``.

    ``stroke`` (m, low < high) places the default offsets and amplitudes on another stage's stroke as they sit on
    :data:`PEA_STROKE`; numbers in the spec are absolute µm.

    Raises
    ------
    ReferenceError_
        With the accepted forms, for anything else.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ReferenceError_("empty reference spec")
    parts = spec.strip().lower().split(":")
    shape = parts[0]
    if shape not in _DEFAULTS:
        raise ReferenceError_(f"unknown reference {spec!r}; use step, ramp, step+ramp, sine:F[:A_um], c1, c2, "
                              "c3, case3 or constant[:LEVEL_um]")
    kw = _DEFAULTS[shape].copy()
    if stroke is not None:
        lo, hi = (float(v) for v in stroke)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ReferenceError_(f"stroke must be finite (low, high) with low < high (m), got {stroke!r}")
        k = (hi - lo) / (PEA_STROKE[1] - PEA_STROKE[0])
        kw["offset"] = lo + (kw["offset"] - PEA_STROKE[0]) * k
        kw["amplitude"] = kw["amplitude"] * k
    shape = "step+ramp" if shape == "stepramp" else shape
    try:
        nums = [float(x) for x in parts[1:]]
    except ValueError:
        raise ReferenceError_(f"reference {spec!r}: numbers expected after ':'") from None
    if len(nums) > (2 if shape == "sine" else 1):  # sine:10:5:99 ran as sine:10:5, the 99 dropped silently
        raise ReferenceError_(f"reference {spec!r}: too many numbers; sine:F[:A_um], constant[:LEVEL_um] or "
                              f"{shape}[:A_um]")
    if shape == "sine":
        if not nums:
            raise ReferenceError_("sine needs a frequency: sine:F (Hz), optionally sine:F:A_um")
        kw["frequency"] = nums[0]
        if len(nums) > 1:
            kw["amplitude"] = nums[1] * UM
        if not 0 < kw["frequency"] <= 500:
            raise ReferenceError_("sine frequency must be in (0, 500] Hz")
    elif shape == "constant" and nums:
        kw["offset"] = nums[0] * UM
    elif nums:
        kw["amplitude"] = nums[0] * UM
    return Reference(shape=shape, **kw)
