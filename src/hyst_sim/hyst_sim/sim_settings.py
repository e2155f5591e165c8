"""The sim node's settings as a frozen, validated dataclass and the plant they describe (no rclpy here)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .errors import SimError
from .plant import PlantConfig
from hyst_common.errors import ConfigError
from hyst_common.profiles import check_range, custom_base
from .scenario import load_scenario

__all__ = ["SimSettings", "plant_config"]


@dataclass(frozen=True)
class SimSettings:
    """All node parameters as plain values (the frozen config the node swaps on a parameter change)."""

    rate: float
    profile: str
    v_min: float
    v_max: float
    slew_max: float
    command_timeout: float
    v_safe: float
    safe_ramp_rate: float
    frame_id: str
    mode: str
    params_file: str
    scenario_file: str
    seed: int
    effects: tuple  # ((name, strength), ...) in EFFECT_NAMES order

    @property
    def dt(self) -> float:
        return 1.0 / self.rate

    def validate(self) -> None:
        """Raise :class:`SimError` with a reason for inconsistent values (ranges are checked by ROS)."""
        if self.profile == "custom" and not self.params_file:  # another stage: its model and range are the user's
            raise SimError("profile custom needs params_file: the stage's model (hyst fit --out)")
        try:
            check_range(self.profile, self.v_min, self.v_max, self.slew_max)
        except ConfigError as err:
            hint = "" if self.profile == "custom" else " (set them in the same call as profile)"
            raise SimError(f"{err}{hint}") from err
        if not self.v_min <= self.v_safe <= self.v_max:
            raise SimError(f"v_safe = {self.v_safe} V must lie in [v_min, v_max] = [{self.v_min}, {self.v_max}] V")
        if self.mode not in ("realtime", "lockstep"):
            raise SimError(f"mode must be 'realtime' or 'lockstep', got {self.mode!r}")


def plant_config(s: SimSettings) -> PlantConfig:
    """The plant a settings object describes: profile or params file, limits, effects, then the scenario."""
    common: dict[str, Any] = dict(sensor=False, seed=s.seed, v_min=s.v_min, v_max=s.v_max, slew_max=s.slew_max,
                                  v_init=s.v_safe)
    if s.params_file:  # a custom stage takes the rig's sensor defaults; its range is in ``common``
        base = custom_base(s.v_min, s.v_max) if s.profile == "custom" else s.profile
        cfg = PlantConfig.from_params_file(s.params_file, base, s.rate, **common)
    else:
        cfg = PlantConfig.for_profile(s.profile, s.rate, **common)
    cfg = cfg.with_strengths(**dict(s.effects))
    if s.scenario_file:
        cfg = load_scenario(s.scenario_file).apply(cfg)
    return cfg
