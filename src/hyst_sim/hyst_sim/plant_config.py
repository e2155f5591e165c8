"""The simulated stage's configuration, :class:`PlantConfig` (frozen: limits, MBW stage, sensor, hidden effects;
built from a profile or a scenario file), and :func:`substeps_for`. :mod:`.plant` runs it and re-exports both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hyst_common.profiles import RATE_TOLERANCE, get_profile
from hyst_model.core import MBWParams, stage_model

from .errors import ConfigError
from .truth_effects import Effects

__all__ = ["PlantConfig", "substeps_for"]


@dataclass(frozen=True)
class PlantConfig:
    """Everything that defines a simulated stage; frozen, so a change is a new object.

    Attributes
    ----------
    mbw : MBWParams
        Hysteresis model with its SI scaling (V in, m out).
    dt : float
        Sample period (s), ``1/rate``.
    v_min, v_max : float
        Amplifier range (V); commands are clipped into it.
    slew_max : float
        Amplifier slew limit (V/s); ``inf`` disables it.
    v_init : float
        Voltage the stage rests at after :meth:`Plant.reset` (V).
    stroke : tuple of float or None
        ``(x_lo, x_hi)`` nominal displacement at ``v_min``/``v_max`` held (m), the scale of asymmetry and
        saturation; None = computed from the MBW rest states.
    mbw_substeps : int
        MBW recursions per sample (input held), see the module docstring.
    effects : Effects
        Physical effects; all off by default.
    seed : int
        Seed of the noise/drift random stream (:meth:`Plant.reset` restarts it).
    """

    mbw: MBWParams
    dt: float = 1e-3
    v_min: float = 0.0
    v_max: float = 150.0
    slew_max: float = math.inf
    v_init: float = 0.0
    stroke: tuple[float, float] | None = None
    mbw_substeps: int = 1
    effects: Effects = field(default_factory=Effects)
    seed: int = 0

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ConfigError` with a reason for any inconsistent setting."""
        if not (math.isfinite(self.dt) and 1e-6 <= self.dt <= 1.0):
            raise ConfigError(f"dt must be in [1 us, 1 s], got {self.dt!r}")
        if not (math.isfinite(self.v_min) and math.isfinite(self.v_max) and self.v_min < self.v_max):
            raise ConfigError(f"need finite v_min < v_max, got [{self.v_min}, {self.v_max}] V")
        if not self.v_min <= self.v_init <= self.v_max:
            raise ConfigError(f"v_init = {self.v_init} V is outside [{self.v_min}, {self.v_max}] V")
        if not self.slew_max > 0:
            raise ConfigError(f"slew_max must be positive (inf = no limit), got {self.slew_max!r}")
        if not (isinstance(self.mbw_substeps, int) and 1 <= self.mbw_substeps <= 64):
            raise ConfigError(f"mbw_substeps must be an integer in [1, 64], got {self.mbw_substeps!r}")
        m = self.mbw
        if not (np.all(np.isfinite(m.vector)) and m.u_scale > 0 and m.y_scale > 0 and math.isfinite(m.offset)):
            raise ConfigError("MBW parameters must be finite with positive u_scale and y_scale")
        if self.stroke is not None and not (len(self.stroke) == 2 and self.stroke[0] < self.stroke[1]):
            raise ConfigError("stroke must be (x_lo, x_hi) with x_lo < x_hi (m)")
        if not isinstance(self.effects, Effects):
            raise ConfigError("effects must be an Effects instance")
        self.effects.validate()

    @property
    def rate(self) -> float:
        """Sample rate (Hz)."""
        return 1.0 / self.dt

    # Constructors ---------------------------------------------------------------------------------------------
    @classmethod
    def for_profile(cls, profile: str = "pea", rate: float = 1000.0, *, mbw: MBWParams | None = None,
                    sensor: bool = True, seed: int = 0, **overrides) -> "PlantConfig":
        """A stage with the profile's amplifier range, slew limit and default model.

        Parameters
        ----------
        profile : {"pea", "gma"}
        rate : float
            Sample rate (Hz).
        mbw : MBWParams, optional
            Stage model; default the profile's (``pea_default()`` for the PEA).
        sensor : bool
            Switch on the profile's sensor noise and quantisation (2 nm each for both profiles).
        **overrides
            Any other :class:`PlantConfig` field.
        """
        prof = get_profile(profile)
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"rate must be a positive number of Hz, got {rate!r}")
        effects = overrides.pop("effects", Effects())
        if sensor:
            effects = effects.with_strengths(noise=prof.sensor_noise, quantization=prof.sensor_resolution)
        kw = dict(mbw=mbw if mbw is not None else stage_model(prof.name), dt=1.0 / rate, v_min=prof.v_min,
                  v_max=prof.v_max, slew_max=prof.slew_max, v_init=prof.v_safe, effects=effects, seed=seed)
        kw.update(overrides)
        return cls(**kw)

    @classmethod
    def from_scenario(cls, path: str | Path, base: "PlantConfig | None" = None) -> "PlantConfig":
        """``base`` (default :meth:`for_profile` ``("pea")``) with a scenario file's hidden effects applied.

        The effects a scenario names replace the base's; the file's contents are never printed (errors name the
        file and the structural problem only). See :mod:`hyst_sim.scenario`.
        """
        from .scenario import load_scenario  # late: file IO is not part of the numerical core

        return load_scenario(path).apply(base if base is not None else cls.for_profile("pea"))

    @classmethod
    def from_params_file(cls, path: str | Path, profile: str = "pea", rate: float = 1000.0,
                         **overrides) -> "PlantConfig":
        """A profile's stage with the MBW model of a params file (``docs/ARCHITECTURE.md``).

        The file's ``dt`` (if given) sets ``mbw_substeps = round(1/(rate·dt))``; a rate faster than the model's
        sample time, or not an integer multiple of it, is refused with a reason.
        """
        from .scenario import load_params_file  # late: file IO is not part of the numerical core

        pf = load_params_file(path)
        if pf.dt is not None and "mbw_substeps" not in overrides:
            overrides["mbw_substeps"] = substeps_for(1.0 / rate, pf.dt)
        return cls.for_profile(profile, rate, mbw=pf.mbw, **overrides)

    def with_strengths(self, **strengths: float) -> "PlantConfig":
        """Copy with new effect strengths (``creep=0.01``, ``delay=3``, ``noise=0``...)."""
        return replace(self, effects=self.effects.with_strengths(**strengths))

    def replace(self, **kw) -> "PlantConfig":
        """Copy with fields replaced (validated)."""
        return replace(self, **kw)


def substeps_for(dt: float, model_dt: float) -> int:
    """MBW recursions per plant sample for a model identified at ``model_dt`` (s); refuses non-integer ratios."""
    ratio = dt / model_dt
    n = int(round(ratio))
    if n < 1 or abs(ratio - n) > RATE_TOLERANCE * max(1.0, ratio):  # a measured period carries the clock's error
        raise ConfigError(f"the model was identified at dt = {model_dt:g} s; the plant period {dt:g} s must be an "
                          f"integer multiple of it (rate <= {1.0 / model_dt:g} Hz, e.g. {1.0 / model_dt:g} or "
                          f"{0.5 / model_dt:g} Hz)")
    return n
