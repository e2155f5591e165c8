"""The controller node's settings as plain values (no rclpy): the gain table every ``<algorithm>.<name>`` parameter
is declared, validated and applied from, the frozen :class:`ControllerSettings` swapped whole on a parameter
change, and the profile's default stage model."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from hyst_common.limits import CommandLimits
from hyst_model.core import PARAM_NAMES, MBWParams, pea_default, stage_model
from hyst_model.core.bounded import mbw_bounded

from .compensation import Compensation, plan_compensation
from .errors import ControlError
from .controllers import gain_table
from .reference import Reference
from .stability import StabilityVerdict, guard

__all__ = ["ControllerSettings", "GAINS", "MODEL_KEYS", "profile_model", "cached_guard", "cached_bounded",
           "model_divergence"]

#: ``{algorithm: (gains dataclass, {gain: Spec})}`` from the controller registry (the gains' own field metadata):
#: the one table every ``<algorithm>.<gain>`` parameter is declared, validated and applied from.
GAINS = gain_table()
MODEL_KEYS = PARAM_NAMES + ("offset", "u_scale", "y_scale")
# The check is a few tens of ms; the on-set callback and the post-set callback both build the settings.
cached_guard = lru_cache(maxsize=64)(guard)
#: The divergence probe (a few ms; MBWParams is frozen, so hashable) for the same two callbacks.
cached_bounded = lru_cache(maxsize=64)(mbw_bounded)


@dataclass(frozen=True)
class ControllerSettings:
    """Every node parameter as plain values; swapped as a whole on a parameter change."""

    algorithm: str
    rate: float
    limits: CommandLimits
    watchdog_periods: int
    state_decimation: int
    #: ``((algorithm, gains), ...)`` as configured, for every algorithm with gains (:data:`GAINS`).
    gain_sets: tuple
    dmrac_initial: str
    model: MBWParams
    reference: Reference | None = None
    #: The params file's effects (innermost first) and their parameters/configuration, dotted (``creep.gain``).
    effects: tuple = ()
    effect_values: tuple = ()
    stability: StabilityVerdict | None = None
    #: '' or why the model diverges within the command limits (the feedback laws run it; see controller_node).
    divergence: str = ""

    def compensation(self) -> Compensation:
        """A fresh compensation (its effects keep per-run state) for the model's effects."""
        vals = dict(self.effect_values)
        return plan_compensation(self.model, self.effects, vals, vals, 1.0 / self.rate)

    def gains(self, algorithm: str):
        """The gains that run: derated by the stability check when the resonance demands it."""
        st = self.stability
        if st is not None and st.algorithm == algorithm:
            return st.gains
        return self.configured(algorithm)

    def configured(self, algorithm: str):
        """The gains as the parameters set them (None for an algorithm without gains)."""
        return dict(self.gain_sets).get(algorithm)


def profile_model(profile: str) -> MBWParams:
    """The default stage model for a profile (:func:`hyst_model.core.stage_model`, as the sim's); an unknown
    profile falls back to the embedded default (the profile's limits report the bad name)."""
    try:
        return stage_model(profile)
    except ValueError:
        return pea_default()


def model_divergence(algorithm: str, model: MBWParams, comp: Compensation | None, limits: CommandLimits,
                     dt: float) -> str:
    """'' when the model stays bounded on commands within ``limits`` (range, and ``slew_max·dt`` per sample:
    :func:`hyst_model.core.bounded.mbw_bounded`); otherwise a warning for the feedback laws, or
    :class:`~hyst_control.errors.ControlError` where the model runs open loop.

    DPPC, DMRAC (and PID, which does not use it) invert the model one step from the measurement, so a model that
    runs away over many samples does not carry them with it. The open-loop inverse follows its own prediction, and
    the Smith predictors (delay, resonance) predict from the base model open loop: those would command whatever the
    runaway prediction says, so they refuse it. The controller node and ``hyst track`` both ask here.
    """
    ok, what = cached_bounded(model, limits.v_min, limits.v_max, limits.slew_max * dt)
    if ok:
        return ""
    why = f"the model diverges on commands within v_min..v_max and slew_max ({what})"
    predicting = [e.name for e in (comp.used if comp is not None else []) if getattr(e, "smith", False)]
    if algorithm == "open_loop" or predicting:
        user = "the open-loop inverse" if algorithm == "open_loop" else f"the {', '.join(predicting)} predictor"
        raise ControlError(f"{why}; {user} follows the model's own prediction, so it is refused: refit the model on "
                           "a record with steps across the range (hyst fit reports this as 'unstable off its record')")
    return (f"{why}: {algorithm} inverts it one step from the measurement and runs, but the open-loop inverse and "
            "the predictors would refuse it; refit on a record with steps across the range")
