"""hyst_emulator: the driver's device emulator (:mod:`hyst_driver.emulator`) on the sim's plant.

The emulator takes its stage as an injected plant, so that a rig running only the driver needs no simulator;
this module is where the two meet: :func:`build_device` and the console script ``hyst_emulator``.
"""
from __future__ import annotations

import sys

from hyst_common.profiles import get_profile
from hyst_driver.emulator import EmulatedDevice
from hyst_driver.emulator import main as emulator_main
from hyst_sim.plant import Plant, PlantConfig

__all__ = ["build_device", "main"]


def build_device(profile: str = "pea", rate: float = 1000.0, scenario: str | None = None,
                 params_file: str | None = None, seed: int = 0) -> EmulatedDevice:
    """An :class:`~hyst_driver.emulator.EmulatedDevice` on the sim's plant for a profile.

    Parameters
    ----------
    profile : str
        ``pea`` or ``gma`` (:mod:`hyst_common.profiles`).
    rate : float
        Sample rate (Hz).
    scenario, params_file : str, optional
        Hidden-effects scenario file and MBW params file for the plant.
    seed : int
        Seed of the plant's sensor noise.
    """
    if params_file:
        cfg = PlantConfig.from_params_file(params_file, profile, rate, seed=seed)
    else:
        cfg = PlantConfig.for_profile(profile, rate, seed=seed)
    if scenario:
        cfg = PlantConfig.from_scenario(scenario, base=cfg)
    return EmulatedDevice(Plant(cfg), get_profile(profile).sensor_resolution)


def main(argv: list[str] | None = None) -> int:
    """Console script ``hyst_emulator`` (``--profile pea --rate 1000 --link PATH``; ``--help`` lists all)."""
    return emulator_main(argv, build=build_device)


if __name__ == "__main__":
    sys.exit(main())
