"""Actuator profiles: the amplifier's voltage range and the stage's nominal stroke and sensor.

A profile is what the rig's hardware fixes (``docs/ARCHITECTURE.md``, shared parameter ``profile``); the sim and
the driver both import it, so a command is clipped to the same range on either side.

==========  ==============  ===========  ==============  ================================================
profile     amplifier       stroke       sensor          default stage model
==========  ==============  ===========  ==============  ================================================
``pea``     0 … 150 V       30 µm        2 nm            :func:`hyst_model.core.pea_default` (Table 4.1)
``gma``     −5 … +5 V       ±20 µm       2 nm            Table 4.1 shape on ±5 V → ±20 µm (see below)
==========  ==============  ===========  ==============  ================================================

The thesis gives no complete identified GMA parameter set (Table 5.3 lists only initial estimates without δ1, δ2),
so the GMA default stage reuses the Table 4.1 loop shape with ``u_scale = 0.5 V`` (±5 V → ±10 model units, the
thesis's own sine amplitude) and ``y_scale`` chosen so that ±5 V held reads ±20 µm (MA-50/6 "±20 µm", Table 5.1).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from .errors import ConfigError

__all__ = ["Profile", "PEA", "GMA", "PROFILES", "get_profile", "clip_command", "clip_kernel",
           "CLIP_RANGE", "CLIP_SLEW", "CLIP_NONFINITE"]

#: Flag bits returned by :func:`clip_command`.
CLIP_RANGE, CLIP_SLEW, CLIP_NONFINITE = 1, 2, 4


@dataclass(frozen=True)
class Profile:
    """Hardware limits of one actuator type.

    Attributes
    ----------
    name : str
        ``"pea"`` or ``"gma"``.
    v_min, v_max : float
        Amplifier input range (V); every command is clipped into it.
    stroke : float
        Nominal full stroke (m) between ``v_min`` and ``v_max`` held at rest.
    sensor_resolution : float
        Displacement sensor resolution (m); the sim quantises to it by default.
    sensor_noise : float
        Standard deviation of the sensor's Gaussian noise (m) in the default sim plant.
    v_safe : float
        Voltage the stage ramps to when commands stop (V): zero field for both actuators.
    slew_max : float
        Default amplifier slew limit (V/s).
    description : str
        One line for logs and help texts.
    """

    name: str
    v_min: float
    v_max: float
    stroke: float
    sensor_resolution: float
    sensor_noise: float
    v_safe: float
    slew_max: float
    description: str = ""

    @property
    def bipolar(self) -> bool:
        """True when the amplifier drives both polarities (GMA); a PEA is unipolar."""
        return self.v_min < 0.0 < self.v_max

    def contains(self, v: float) -> bool:
        """True when ``v`` (V) is a finite voltage inside the amplifier range."""
        return bool(np.isfinite(v) and self.v_min <= v <= self.v_max)

    def model(self):
        """Default stage model (:class:`hyst_model.core.MBWParams`) for this profile, SI scaling included."""
        return _default_model(self.name)


#: Piezoelectric stage of thesis ch. 4: 0–150 V amplifier (6 kHz bandwidth), 30 µm travel, 2 nm sensor.
PEA = Profile("pea", 0.0, 150.0, 30e-6, 2e-9, 2e-9, 0.0, 1.0e5,
              "piezoelectric stage, 0-150 V, 30 um, 2 nm sensor")
#: Giant-magnetostrictive actuator of thesis ch. 5: MO24BR driver input ±5 V, MA-50/6 ±20 µm.
GMA = Profile("gma", -5.0, 5.0, 40e-6, 2e-9, 2e-9, 0.0, 1.0e4,
              "giant-magnetostrictive actuator, driver input +-5 V, +-20 um")

PROFILES: dict[str, Profile] = {"pea": PEA, "gma": GMA}


def get_profile(name: str) -> Profile:
    """Profile by name (case-insensitive).

    Raises
    ------
    ConfigError
        Unknown name; the message lists the valid ones.
    """
    try:
        return PROFILES[str(name).strip().lower()]
    except KeyError:
        raise ConfigError(f"unknown profile {name!r}; choose one of {', '.join(PROFILES)}") from None


def clip_command(v: float, v_min: float, v_max: float, v_prev: float, max_step: float) -> tuple[float, int]:
    """Clip one command to a range and a per-sample slew step, the way the amplifier sees it.

    The simulated plant's compiled loop calls the same function (:func:`clip_kernel`), so the sim and a driver
    that imports this clip identically.

    Parameters
    ----------
    v : float
        Commanded voltage (V); NaN/inf keep the previous output.
    v_min, v_max : float
        Allowed range (V), inside the profile.
    v_prev : float
        Voltage applied one sample earlier (V).
    max_step : float
        Largest change per sample (V), ``slew_max * dt``; ``inf`` disables the slew limit.

    Returns
    -------
    v_applied : float
    flags : int
        Bit 0 (:data:`CLIP_RANGE`) range clipped, bit 1 (:data:`CLIP_SLEW`) slew limited, bit 2
        (:data:`CLIP_NONFINITE`) non-finite command replaced by the previous value.
    """
    va, fl = clip_kernel(float(v), float(v_min), float(v_max), float(v_prev), float(max_step))
    return float(va), int(fl)


@njit(cache=True)
def clip_kernel(v: float, v_min: float, v_max: float, v_prev: float, max_step: float):
    """Compiled body of :func:`clip_command` (float arguments only).

    Order: range, then slew relative to ``v_prev``, then the range again, so that the output is inside
    ``[v_min, v_max]`` even when ``v_prev`` is not (e.g. right after the range was narrowed).
    """
    flags = 0
    if not np.isfinite(v):
        v = v_prev
        flags = 4
    else:
        if v < v_min:
            v = v_min
            flags |= 1
        elif v > v_max:
            v = v_max
            flags |= 1
        dv = v - v_prev
        if dv > max_step:
            v = v_prev + max_step
            flags |= 2
        elif dv < -max_step:
            v = v_prev - max_step
            flags |= 2
    if v < v_min:
        v = v_min
        flags |= 1
    elif v > v_max:
        v = v_max
        flags |= 1
    return v, flags


@lru_cache(maxsize=None)
def _default_model(name: str):
    from hyst_model.core import mbw_rest_state, pea_default  # late: keep the profile table importable alone

    pea = pea_default()
    if name == "pea":
        return pea
    if name == "gma":
        u_scale = GMA.v_max / 10.0
        y_full = float(mbw_rest_state(pea.vector, GMA.v_max / u_scale))
        return pea.replace(u_scale=u_scale, y_scale=(GMA.stroke / 2.0) / y_full, offset=0.0)
    raise ConfigError(f"no default model for profile {name!r}")
