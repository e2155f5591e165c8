"""A stage without hysteresis for the device emulator when the simulator is not installed.

The emulator (:mod:`.emulator`) takes its stage as an injected plant, so that a rig running only the driver needs
no simulator. :class:`LinearStage` is the plant this package brings itself: the profile's amplifier (range and
slew, through the one limiter :func:`hyst_common.limits.limit_step`) and a linear stroke

    y = stroke · (u − v_min) / (v_max − v_min) + noise,   quantised to the sensor resolution,

which is all the driver needs to be exercised end to end (handshake, streaming, limits, faults, reconnects). For
a hysteretic stage with hidden effects use ``hyst_emulator`` (:mod:`hyst_bringup.emulator`), which injects the
sim's plant.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import NamedTuple

from hyst_common.limits import limit_step
from hyst_common.profiles import Profile, get_profile

from .emulated_device import EmulatedDevice
from .errors import ConfigError

__all__ = ["LinearStage", "LinearStageConfig", "linear_device"]


@dataclass(frozen=True)
class LinearStageConfig:
    """What :class:`~.emulated_device.EmulatedDevice` reads of a plant's configuration (V, s)."""

    v_min: float
    v_max: float
    dt: float
    slew_max: float
    v_init: float


class LinearStep(NamedTuple):
    """One sample: sensor reading ``y`` (m), applied voltage ``u_applied`` (V), ``clipped`` by the amplifier."""

    y: float
    u_applied: float
    clipped: bool


class LinearStage:
    """A linear stage behind the profile's amplifier (see the module docstring).

    Parameters
    ----------
    profile : Profile
        Amplifier range, slew limit, stroke, sensor resolution and noise.
    rate : float
        Sample rate (Hz).
    seed : int
        Seed of the sensor noise.
    noise : float, optional
        Sensor noise standard deviation (m); the profile's by default, 0 for exact readings.
    """

    def __init__(self, profile: Profile, rate: float, seed: int = 0, noise: float | None = None) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"rate must be a positive number of Hz, not {rate!r}")
        self.profile = profile
        v_init = min(max(profile.v_safe, profile.v_min), profile.v_max)
        self.config = LinearStageConfig(profile.v_min, profile.v_max, 1.0 / rate, profile.slew_max, v_init)
        self.noise = profile.sensor_noise if noise is None else float(noise)
        self.seed = seed
        self._gain = profile.stroke / (profile.v_max - profile.v_min)
        self.reset()

    @property
    def u_applied(self) -> float:
        """Voltage applied at the last sample (V)."""
        return self._u

    def reset(self, v0: float | None = None) -> None:
        """Put the stage at ``v0`` (V, default ``config.v_init``) and restart the noise."""
        c = self.config
        self._u = c.v_init if v0 is None else min(max(float(v0), c.v_min), c.v_max)
        self._rng = random.Random(self.seed)

    def step(self, v: float) -> LinearStep:
        """Apply ``v`` (V) through the amplifier's range and slew limit for one sample; read the sensor."""
        c = self.config
        u, flags = limit_step(float(v), c.v_min, c.v_max, self._u, c.slew_max * c.dt)
        self._u = float(u)
        y = self._gain * (self._u - c.v_min)
        if self.noise > 0:
            y += self._rng.gauss(0.0, self.noise)
        q = self.profile.sensor_resolution
        if q > 0:
            y = round(y / q) * q
        return LinearStep(y, self._u, flags != 0)


def linear_device(profile: str = "pea", rate: float = 1000.0, scenario: str | None = None,
                  params_file: str | None = None, seed: int = 0,
                  v_range: tuple[float | None, float | None] | None = None) -> EmulatedDevice:
    """An :class:`~.emulated_device.EmulatedDevice` on a :class:`LinearStage` of a profile (the emulator's
    default ``build``). ``scenario`` and ``params_file`` describe a hysteretic stage, and ``profile custom`` (with
    ``v_range``) another stage's model: refused here with the way to get one."""
    if scenario or params_file or profile == "custom":
        raise ConfigError("--scenario, --params-file and --profile custom need the simulated stage: use hyst_emulator "
                          "(package hyst_bringup), which runs the emulator on the sim's plant")
    p = get_profile(profile)
    return EmulatedDevice(LinearStage(p, rate, seed=seed), p.sensor_resolution)
