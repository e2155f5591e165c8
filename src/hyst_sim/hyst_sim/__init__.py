"""hyst_sim: the simulated stage that stands in for the driver, and the bag recorder/player.

Layers: :mod:`hyst_sim.plant` and :mod:`hyst_sim.truth_effects` (numerical core, numpy/numba only),
:mod:`hyst_common.profiles` (amplifier/stage limits shared with the driver and the controller, re-exported here),
:mod:`hyst_sim.scenario` and :mod:`hyst_sim.bagio` (file IO), ``*_node.py`` (thin rclpy nodes; the only modules
importing rclpy).
"""
import hyst_common  # noqa: F401  first: sets single-threaded BLAS before numpy loads (hyst_common.blas)
from hyst_common.profiles import GMA, PEA, PROFILES, Profile, get_profile

from .errors import BagError, ConfigError, ScenarioError, SimError
from .plant import CLIP_NONFINITE, CLIP_RANGE, CLIP_SLEW, Plant, PlantConfig, RunResult, StepResult
from .scenario import Scenario, load_scenario, scenario_dir
from .truth_effects import EFFECT_NAMES, Effects

__all__ = ["BagError", "ConfigError", "ScenarioError", "SimError",
           "CLIP_NONFINITE", "CLIP_RANGE", "CLIP_SLEW", "Plant", "PlantConfig", "RunResult", "StepResult",
           "GMA", "PEA", "PROFILES", "Profile", "get_profile",
           "Scenario", "load_scenario", "scenario_dir", "EFFECT_NAMES", "Effects"]
