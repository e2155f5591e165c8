"""Actuator profiles: the amplifier's voltage range and the stage's nominal stroke and sensor.

A profile is what the rig's hardware fixes (``docs/ARCHITECTURE.md``, shared parameter ``profile``); the sim, the
driver and the controller all import it from here, so a command is limited to the same range everywhere (by the
one limiter, :mod:`hyst_common.limits`). The default stage *model* of a profile is a model, not a hardware fact:
:func:`hyst_model.core.stage_model`.

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

import math
from dataclasses import dataclass

from .errors import ConfigError
from .limits import CommandLimits

__all__ = ["RATE_TOLERANCE", "same_rate", "Profile", "PEA", "GMA", "PROFILES", "get_profile", "V_SPAN",
           "PEA_LIMITS", "GMA_LIMITS", "CUSTOM_V_MAX", "CUSTOM_SWING_TIME", "custom_limits", "custom_range",
           "rest_voltage", "custom_slew", "custom_base", "check_range"]


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
        return bool(math.isfinite(v) and self.v_min <= v <= self.v_max)

    def limits(self, **kw) -> CommandLimits:
        """The profile's range, slew limit and safe voltage as :class:`~hyst_common.limits.CommandLimits` (``kw``
        overrides fields, e.g. ``v_max``)."""
        return CommandLimits(**{"v_min": self.v_min, "v_max": self.v_max, "slew_max": self.slew_max,
                         "v_safe": self.v_safe, **kw})


#: Piezoelectric stage of thesis ch. 4: 0–150 V amplifier (6 kHz bandwidth), 30 µm travel, 2 nm sensor.
PEA = Profile("pea", 0.0, 150.0, 30e-6, 2e-9, 2e-9, 0.0, 1.0e5,
              "piezoelectric stage, 0-150 V, 30 um, 2 nm sensor")
#: Giant-magnetostrictive actuator of thesis ch. 5: MO24BR driver input ±5 V, MA-50/6 ±20 µm.
GMA = Profile("gma", -5.0, 5.0, 40e-6, 2e-9, 2e-9, 0.0, 1.0e4,
              "giant-magnetostrictive actuator, driver input +-5 V, +-20 um")

PROFILES: dict[str, Profile] = {"pea": PEA, "gma": GMA}
#: Lowest and highest voltage of any profile (V): the static range of the nodes' voltage parameters (-5, 150).
V_SPAN = (min(p.v_min for p in PROFILES.values()), max(p.v_max for p in PROFILES.values()))


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


#: Command limits of the PEA amplifier 0–150 V (thesis 4.3.1), slew 1e5 V/s, for the controllers.
PEA_LIMITS = PEA.limits()
#: Command limits of the GMA driver input ±5 V (thesis Table 5.1), slew 1e4 V/s.
GMA_LIMITS = GMA.limits()


#: Largest |voltage| (V) a user may give another stage's amplifier (``profile custom``): high-voltage piezo
#: amplifiers reach about 1 kV.
CUSTOM_V_MAX = 1000.0
#: Default slew limit of another stage's amplifier: a full swing in this many seconds (the PEA's 1e5 V/s swings its
#: 150 V in 1.5 ms, the GMA's 1e4 V/s its 10 V in 1 ms) — protective, not a hardware fact; give it where known.
CUSTOM_SWING_TIME = 1e-3


def rest_voltage(v_min: float, v_max: float) -> float:
    """The voltage a stage rests at (V): 0 V (zero field) where ``[v_min, v_max]`` holds it, else the end nearer
    0 V — the PEA's and the GMA's 0 V, 20 V of a 20–120 V stage. The excitation starts and ends there too."""
    return min(max(0.0, v_min), v_max)


def custom_slew(v_min: float, v_max: float) -> float:
    """Default slew limit (V/s) of another stage's amplifier: a full swing in :data:`CUSTOM_SWING_TIME`
    (1e4 V/s, the GMA's, while no range is given yet: a node declares it before it is checked)."""
    span = v_max - v_min
    return span / CUSTOM_SWING_TIME if span > 0 else 1e4


def custom_base(v_min: float, v_max: float) -> str:
    """The profile whose sensor and model defaults another stage's simulation takes: ``gma`` for a range about
    0 V, else ``pea`` (both have the rig's 2 nm sensor; the stage's range and model are its own)."""
    return "gma" if v_min < 0.0 < v_max else "pea"


def custom_limits(v_min: float, v_max: float, slew_max: float | None = None) -> CommandLimits:
    """Command limits of a stage outside the two profiles, from its amplifier range (V) as the user gives it.

    The safe voltage is 0 V where the range holds it (zero field), else the end nearer 0 V; the slew limit
    defaults to a full swing in :data:`CUSTOM_SWING_TIME`.

    Raises
    ------
    ConfigError
        A bound that is not finite, beyond ±:data:`CUSTOM_V_MAX`, or an empty range.
    """
    lo, hi = float(v_min), float(v_max)
    if not (math.isfinite(lo) and math.isfinite(hi) and -CUSTOM_V_MAX <= lo < hi <= CUSTOM_V_MAX):
        raise ConfigError(f"a custom amplifier range needs finite v_min < v_max within ±{CUSTOM_V_MAX:g} V, "
                          f"got {lo:g}..{hi:g} V")
    slew = custom_slew(lo, hi) if slew_max is None else float(slew_max)
    return CommandLimits(v_min=lo, v_max=hi, slew_max=slew, v_safe=rest_voltage(lo, hi))


def custom_range(v_min: float, v_max: float, slew_max: float | None = None) -> CommandLimits:
    """:func:`custom_limits` for ``profile custom``, refused in the one wording the nodes and the sim share.

    Raises
    ------
    ConfigError
        ``profile custom needs v_min and v_max, the amplifier's range: ...``
    """
    try:
        return custom_limits(v_min, v_max, slew_max)
    except ConfigError as err:
        raise ConfigError(f"profile custom needs v_min and v_max, the amplifier's range: {err}") from err


def check_range(profile: str, v_min: float, v_max: float, slew_max: float | None = None) -> None:
    """Refuse ``[v_min, v_max]`` where the profile's amplifier has no such range: inside the profile's for ``pea``
    and ``gma``, a finite range within ±:data:`CUSTOM_V_MAX` for ``custom`` — the one check of the driver, the
    sim and the controller.

    Raises
    ------
    ConfigError
        With the reason (an unknown profile name too).
    """
    name = str(profile).strip().lower()
    if name == "custom":
        custom_range(v_min, v_max, slew_max)
        return
    prof = get_profile(name)
    if not prof.v_min <= v_min < v_max <= prof.v_max:
        raise ConfigError(f"need {prof.v_min:g} <= v_min < v_max <= {prof.v_max:g} V for profile {prof.name} (the "
                          f"amplifier's range), got v_min={v_min:g}, v_max={v_max:g}")


#: Relative difference between a model's sample period and a loop's within which the per-sample model runs at the
#: loop's rate: a stage's stamps carry its clock's error (20 ppm) and jitter, which a record's median period keeps
#: (1.00002 ms and 1.000656 ms for 1 ms were refused at 1e-6); 0.1 % changes a recursion by as much as 0.1 % of
#: its rate terms.
RATE_TOLERANCE = 1e-3


def same_rate(model_dt: float, rate: float) -> bool:
    """True when a model identified at ``model_dt`` (s) runs per sample at ``rate`` (Hz): :data:`RATE_TOLERANCE`."""
    return abs(float(model_dt) * float(rate) - 1.0) <= RATE_TOLERANCE
