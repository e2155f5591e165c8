"""Physical effects of the simulated stage beyond MBW hysteresis ("truth models"), each switchable.

Every effect is a frozen dataclass with one scalar ``strength`` (0 = off; the sim node exposes it as the ROS
parameter ``effects.<name>``) and a few shape settings that only a scenario file changes. Their per-sample
arithmetic is compiled here (``*_kernel`` functions) and composed by :mod:`hyst_sim.plant` in this order, which
is the physical signal chain of a stage::

    u_applied ─ delay ─▶ MBW (3.21) ─ asymmetry ─ creep ─ saturation ─ dynamics ─▶ x (m)
                                                      x ─ + drift ─ + noise ─ quantization ─▶ y_measured

===============  =====================  ==================================================================
effect           strength (unit)        model
===============  =====================  ==================================================================
``creep``        1/decade               log-in-time creep: after a step Δ the displacement grows by
                                        ≈ strength·Δ per decade of time (bank of first-order lags)
``asymmetry``    fraction of stroke     even-order (quadratic) bow of the displacement, strength·stroke at
                                        mid-stroke, zero at both ends: breaks the loop's point symmetry
``dynamics``     Hz                     lightly damped 2nd-order stage resonance (unit DC gain), exact ZOH
``delay``        samples (int)          transport delay between amplifier and stage
``drift``        m/s                    sensor offset drift: linear + slow thermal sine + random walk
``saturation``   fraction of stroke     smooth stroke limit that removes ≈ 1.2·strength·stroke at the end(s)
``noise``        m (std)                white Gaussian sensor noise
``quantization`` m                      sensor resolution (rounding to a multiple)
===============  =====================  ==================================================================
"""
from __future__ import annotations

import math
from dataclasses import Field, dataclass, field, fields, replace
from typing import Any, ClassVar

import numpy as np
from numba import njit

from .errors import ConfigError

__all__ = [
    "EFFECT_NAMES", "StrengthSpec", "Creep", "Asymmetry", "Dynamics", "Delay", "Drift", "Saturation", "Noise",
    "Quantization", "Effects", "creep_kernel", "asymmetry_kernel", "saturation_kernel", "dynamics_kernel",
]

EFFECT_NAMES: tuple[str, ...] = ("creep", "asymmetry", "dynamics", "delay", "drift", "saturation", "noise",
                                 "quantization")


@dataclass(frozen=True)
class StrengthSpec:
    """Range and meaning of an effect's ``strength`` (one place for validation and ROS descriptors)."""

    lower: float
    upper: float
    unit: str
    doc: str
    integer: bool = False


class _Effect:
    """Shared behaviour: validation of ``strength`` against :attr:`SPEC`, ``enabled``."""

    SPEC: ClassVar[StrengthSpec]
    name: ClassVar[str]
    strength: float
    # Every effect is a frozen dataclass (the subclasses): declared so dataclasses.fields/replace take an effect
    # class or object typed as _Effect. An annotation only: nothing is set here.
    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

    @property
    def enabled(self) -> bool:
        return self.strength != 0

    def validate(self) -> None:
        """Raise :class:`ConfigError` with a reason when a setting is out of range."""
        s = self.strength
        if self.SPEC.integer and (not isinstance(s, (int, np.integer)) or isinstance(s, bool)):
            raise ConfigError(f"effects.{self.name} must be an integer number of samples, got {s!r}")
        if not (isinstance(s, (int, float, np.integer, np.floating)) and math.isfinite(s)):
            raise ConfigError(f"effects.{self.name} must be a finite number, got {s!r}")
        if not self.SPEC.lower <= s <= self.SPEC.upper:
            raise ConfigError(f"effects.{self.name} = {s} is outside [{self.SPEC.lower}, {self.SPEC.upper}] "
                              f"{self.SPEC.unit}".rstrip())
        self._validate_shape()

    def _validate_shape(self) -> None:  # overridden where shape settings exist
        pass


@dataclass(frozen=True)
class Creep(_Effect):
    """Logarithmic creep, ``y(t) ≈ y_0 + strength·Δ·log10(t/t0)`` after a step Δ of the hysteretic displacement.

    Implemented as ``n`` first-order lags with time constants log-spaced from ``tau_min`` to ``tau_max``
    (``per_decade`` per decade): the creep term is ``-(strength/per_decade)·Σ_i (x_q − c_i)`` with
    ``c_i ← a_i c_i + (1 − a_i) x_q``, ``a_i = exp(−dt/τ_i)`` (exact for a held input). At rest every ``c_i``
    equals ``x_q``, so the long-held static map is the MBW's own (150 V held still reads 30 µm); between
    ``tau_min`` and ``tau_max`` the step response is linear in log time, unlike the MBW's single δ relaxation.
    """

    name: ClassVar[str] = "creep"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 0.2, "1/decade",
                                                "creep per decade of time as a fraction of a step (0 = off)")
    strength: float = 0.0
    tau_min: float = 0.01
    tau_max: float = 300.0
    per_decade: int = 4

    def _validate_shape(self) -> None:
        if not (0 < self.tau_min < self.tau_max and math.isfinite(self.tau_max)):
            raise ConfigError("creep needs 0 < tau_min < tau_max (s)")
        if not (isinstance(self.per_decade, int) and 1 <= self.per_decade <= 20):
            raise ConfigError("creep per_decade must be an integer in [1, 20]")

    def coefficients(self, dt: float) -> tuple[np.ndarray, float]:
        """Lag poles ``a_i`` and the gain ``strength / per_decade`` for sample time ``dt`` (s)."""
        if not self.enabled:
            return np.zeros(0), 0.0
        n = int(round(self.per_decade * math.log10(self.tau_max / self.tau_min))) + 1
        tau = np.logspace(math.log10(self.tau_min), math.log10(self.tau_max), n)
        return np.exp(-dt / tau), float(self.strength) / self.per_decade


@dataclass(frozen=True)
class Asymmetry(_Effect):
    """Even-order bow: ``x_a = x − strength·S·(1 − q²)``, ``q = (x − x_mid)/(S/2)``, ``S`` the nominal stroke.

    Zero at both ends of the stroke, largest (``strength·S``) at mid-stroke; a sine about mid-stroke gets a
    second harmonic the point-symmetric MBW cannot produce.
    """

    name: ClassVar[str] = "asymmetry"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(-0.2, 0.2, "", "quadratic bow at mid-stroke, fraction of stroke")
    strength: float = 0.0


@dataclass(frozen=True)
class Dynamics(_Effect):
    """Stage resonance ``ωn²/(s² + 2ζωn s + ωn²)``, ``strength`` = fn (Hz), ``damping`` = ζ.

    Discretised exactly for a zero-order-held input (matrix exponential); the sample ``k`` reads the state at
    the end of the period over which input ``k`` was held, the same timing convention as the MBW (``y_k``
    responds to ``u_k``). Frequencies above Nyquist alias, as they would on the rig.
    """

    name: ClassVar[str] = "dynamics"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 20000.0, "Hz", "stage resonance frequency (0 = off)")
    strength: float = 0.0
    damping: float = 0.05

    def _validate_shape(self) -> None:
        if self.enabled and self.strength < 1.0:
            raise ConfigError("effects.dynamics must be 0 (off) or at least 1 Hz")
        if not 0.001 <= self.damping <= 2.0:
            raise ConfigError("dynamics damping must be in [0.001, 2]")

    def coefficients(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(Phi (2, 2), Gamma (2,))`` of ``x_k = Phi x_{k−1} + Gamma u_k`` (state: position, velocity)."""
        from scipy.linalg import expm  # late: only needed when the effect is on

        w = 2.0 * math.pi * float(self.strength)
        a = np.array([[0.0, 1.0], [-w * w, -2.0 * self.damping * w]])
        m = np.zeros((3, 3))
        m[:2, :2] = a
        m[1, 2] = w * w
        e = expm(m * dt)
        return np.ascontiguousarray(e[:2, :2]), np.ascontiguousarray(e[:2, 2])


@dataclass(frozen=True)
class Delay(_Effect):
    """Transport delay of ``strength`` samples between the applied voltage and the stage."""

    name: ClassVar[str] = "delay"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0, 1000, "samples", "input delay in samples (0 = off)", True)
    strength: int = 0


@dataclass(frozen=True)
class Drift(_Effect):
    """Sensor offset drift, input-independent: ``d(t) = r·t + A·sin(2πt/T) + w(t)``.

    ``r`` = strength (m/s); the thermal sine has period ``period`` (s) and amplitude ``A = sine·r·T/(2π)``
    (``sine`` = 1 makes its peak slope equal to r); ``w`` is a random walk with ``walk·r`` m/√s diffusion.
    """

    name: ClassVar[str] = "drift"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 1e-6, "m/s", "sensor offset drift rate (0 = off)")
    strength: float = 0.0
    period: float = 60.0
    sine: float = 0.5
    walk: float = 0.5

    def _validate_shape(self) -> None:
        if not (self.period > 0 and math.isfinite(self.period) and self.sine >= 0 and self.walk >= 0):
            raise ConfigError("drift needs period > 0, sine >= 0 and walk >= 0")


@dataclass(frozen=True)
class Saturation(_Effect):
    """Smooth stroke limit: the end(s) of the stroke lose ``strength·S`` plus a soft knee of width ``2·strength·S``.

    Linear inside the knee, ``tanh`` beyond it (C¹ at the knee). A unipolar stage (PEA) saturates at the top
    only; a bipolar one (GMA) at both ends (``two_sided``: None = from the profile). Two-sided above a strength
    of 1/6 the knees would overlap; they meet at mid-stroke instead (:func:`saturation_kernel`).
    """

    name: ClassVar[str] = "saturation"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 0.4, "", "stroke lost at the end(s), fraction of stroke")
    strength: float = 0.0
    two_sided: bool | None = None


@dataclass(frozen=True)
class Noise(_Effect):
    """White Gaussian sensor noise with standard deviation ``strength`` (m)."""

    name: ClassVar[str] = "noise"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 1e-6, "m", "sensor noise standard deviation (0 = off)")
    strength: float = 0.0


@dataclass(frozen=True)
class Quantization(_Effect):
    """Sensor resolution: the reading is rounded to a multiple of ``strength`` (m)."""

    name: ClassVar[str] = "quantization"
    SPEC: ClassVar[StrengthSpec] = StrengthSpec(0.0, 1e-6, "m", "sensor resolution (0 = off)")
    strength: float = 0.0


_CLASSES: dict[str, type[_Effect]] = {c.name: c for c in (Creep, Asymmetry, Dynamics, Delay, Drift, Saturation, Noise,
                                                           Quantization)}


@dataclass(frozen=True)
class Effects:
    """All effects of one plant; every one off by default."""

    creep: Creep = field(default_factory=Creep)
    asymmetry: Asymmetry = field(default_factory=Asymmetry)
    dynamics: Dynamics = field(default_factory=Dynamics)
    delay: Delay = field(default_factory=Delay)
    drift: Drift = field(default_factory=Drift)
    saturation: Saturation = field(default_factory=Saturation)
    noise: Noise = field(default_factory=Noise)
    quantization: Quantization = field(default_factory=Quantization)

    @staticmethod
    def spec(name: str) -> StrengthSpec:
        """Strength range of effect ``name`` (raises :class:`ConfigError` for unknown names)."""
        return Effects.effect_class(name).SPEC

    @staticmethod
    def effect_class(name: str) -> type[_Effect]:
        try:
            return _CLASSES[name]
        except KeyError:
            raise ConfigError(f"unknown effect {name!r}; choose one of {', '.join(EFFECT_NAMES)}") from None

    def strengths(self) -> dict[str, float]:
        """``{name: strength}`` for every effect."""
        return {f.name: getattr(self, f.name).strength for f in fields(self)}

    def active(self) -> tuple[str, ...]:
        """Names of the effects that are on."""
        return tuple(n for n, s in self.strengths().items() if s != 0)

    def with_strengths(self, **strengths: float) -> "Effects":
        """Copy with new strengths (shape settings kept), validated."""
        new = {}
        for name, s in strengths.items():
            cls = self.effect_class(name)
            if cls.SPEC.integer and isinstance(s, float) and s.is_integer():
                s = int(s)
            new[name] = replace(getattr(self, name), strength=s)
        out = replace(self, **new)
        out.validate()
        return out

    def with_effects(self, **effects) -> "Effects":
        """Copy with whole effect objects replaced (e.g. from a scenario), validated."""
        for name, e in effects.items():
            if not isinstance(e, self.effect_class(name)):
                raise ConfigError(f"effect {name!r} needs a {self.effect_class(name).__name__}")
        out = replace(self, **effects)
        out.validate()
        return out

    def validate(self) -> None:
        for f in fields(self):
            getattr(self, f.name).validate()


# Compiled per-sample arithmetic, composed by hyst_sim.plant ----------------------------------------------------

@njit(cache=True)
def creep_kernel(x: float, c: np.ndarray, a: np.ndarray, gain: float) -> float:
    """Advance the creep lags ``c`` (in place) with input ``x`` (m) and return ``x`` plus the creep term."""
    s = 0.0
    for i in range(c.shape[0]):
        c[i] = a[i] * c[i] + (1.0 - a[i]) * x
        s += x - c[i]
    return x - gain * s


@njit(cache=True)
def asymmetry_kernel(x: float, beta: float, x_mid: float, half: float) -> float:
    """Quadratic bow ``x − beta·2·half·(1 − q²)`` with ``q = (x − x_mid)/half`` (``half`` = S/2)."""
    q = (x - x_mid) / half
    return x - beta * 2.0 * half * (1.0 - q * q)


@njit(cache=True)
def saturation_kernel(x: float, lo: float, hi: float, w: float) -> float:
    """Soft limit to ``[lo, hi]`` with knees of width ``w`` (identity between ``lo + w`` and ``hi − w``).

    Two-sided knees never overlap: the width acting is at most ``(hi − lo)/2``, so strong limits have their knees
    meet at mid-range with slope 1 on both sides (monotonic, C¹), as hyst_model's saturation effect
    (``knee_width``). Overlapping knees were a different map depending on which branch was tested first.
    """
    w = min(w, 0.5 * (hi - lo))  # lo = −inf (one-sided): w unchanged
    k = hi - w
    if x > k:
        return k + w * math.tanh((x - k) / w)
    k = lo + w
    if x < k:
        return k - w * math.tanh((k - x) / w)
    return x


@njit(cache=True)
def dynamics_kernel(z: np.ndarray, phi: np.ndarray, gam: np.ndarray, x: float) -> float:
    """Advance the resonance state ``z`` (in place) with held input ``x`` and return its position."""
    z0 = phi[0, 0] * z[0] + phi[0, 1] * z[1] + gam[0] * x
    z1 = phi[1, 0] * z[0] + phi[1, 1] * z[1] + gam[1] * x
    z[0] = z0
    z[1] = z1
    return z0
