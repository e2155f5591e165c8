"""hyst_emulator: the driver's device emulator (:mod:`hyst_driver.emulator`) on the sim's plant.

The emulator takes its stage as an injected plant, so that a rig running only the driver needs no simulator;
this module is where the two meet: :func:`build_device` and the console script ``hyst_emulator``.
"""
from __future__ import annotations

import sys

from hyst_common.errors import ConfigError
from hyst_common.profiles import PEA, custom_base, custom_limits, get_profile
from hyst_driver.emulator import EmulatedDevice
from hyst_driver.emulator import main as emulator_main
from hyst_sim.plant import Plant, PlantConfig

__all__ = ["build_device", "main"]


def build_device(profile: str = "pea", rate: float = 1000.0, scenario: str | None = None,
                 params_file: str | None = None, seed: int = 0,
                 v_range: tuple[float | None, float | None] | None = None) -> EmulatedDevice:
    """An :class:`~hyst_driver.emulator.EmulatedDevice` on the sim's plant for a profile.

    Parameters
    ----------
    profile : str
        ``pea``, ``gma`` (:mod:`hyst_common.profiles`) or ``custom``: another stage, the model of ``params_file``
        over ``v_range`` with the rig's sensor (as the sim node's ``profile custom``).
    rate : float
        Sample rate (Hz).
    scenario, params_file : str, optional
        Hidden-effects scenario file and MBW params file for the plant.
    seed : int
        Seed of the plant's sensor noise.
    v_range : (float, float), optional
        ``(v_min, v_max)`` of a custom stage's amplifier (V); refused for the two profiles, which have their own.

    Raises
    ------
    ConfigError
        ``custom`` without its params file or range, or a range beyond ±1 kV.
    """
    if profile == "custom":
        if not params_file:
            raise ConfigError("--profile custom needs --params-file: the stage's model (hyst fit --out)")
        lo, hi = v_range if v_range is not None else (None, None)
        if lo is None or hi is None:
            raise ConfigError("--profile custom needs --v-min and --v-max: the stage amplifier's range (V)")
        lim = custom_limits(lo, hi)
        cfg = PlantConfig.from_params_file(params_file, custom_base(lim.v_min, lim.v_max), rate, seed=seed,
                                           v_min=lim.v_min, v_max=lim.v_max, slew_max=lim.slew_max,
                                           v_init=lim.v_safe)
        resolution = PEA.sensor_resolution  # the rig's sensor
    else:
        if v_range is not None:
            raise ConfigError(f"--v-min/--v-max set a custom stage's range; profile {profile} has its own")
        if params_file:
            cfg = PlantConfig.from_params_file(params_file, profile, rate, seed=seed)
        else:
            cfg = PlantConfig.for_profile(profile, rate, seed=seed)
        resolution = get_profile(profile).sensor_resolution
    if scenario:
        cfg = PlantConfig.from_scenario(scenario, base=cfg)
    return EmulatedDevice(Plant(cfg), resolution)


def main(argv: list[str] | None = None) -> int:
    """Console script ``hyst_emulator`` (``--profile pea --rate 1000 --link PATH``; ``--help`` lists all)."""
    return emulator_main(argv, build=build_device)


if __name__ == "__main__":
    sys.exit(main())
