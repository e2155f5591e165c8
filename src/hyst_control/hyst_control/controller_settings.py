"""The controller node's settings as plain values (no rclpy): the gain table every ``<algorithm>.<name>`` parameter
is declared, validated and applied from, the frozen :class:`ControllerSettings` swapped whole on a parameter
change and built, with every check, by :func:`read_settings`, and the profile's default stage model."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from hyst_common.limits import CommandLimits
from hyst_common.profiles import check_range, same_rate
from hyst_model.core import PARAM_NAMES, MBWParams, pea_default, stage_model
from hyst_model.core.bounded import mbw_bounded

from .base import check_model
from .compensation import Compensation, plan_compensation
from .dmrac import TABLE53
from .errors import ControlError
from .controllers import ALGORITHMS, gain_table, make_controller
from .reference import Reference, parse_reference
from .stability import POLICIES, StabilityVerdict, guard, identified_resonance

__all__ = ["ControllerSettings", "GAINS", "MODEL_KEYS", "profile_model", "cached_guard", "cached_bounded",
           "model_divergence", "read_settings"]

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
    #: The model's rest displacement at ``v_min`` and ``v_max`` (m), or None where it has none (a model pushed
    #: that diverges): what the stage can reach, and what a sensor reading can plausibly be.
    stroke: tuple[float, float] | None = None
    #: Rate (V/s) of the watchdog's ramp to ``v_safe`` (as the driver's and the sim's own timeouts ramp).
    safe_ramp_rate: float = 100.0

    def plausible(self, y: float, u: float | None) -> str:
        """'' for a state sample the stage can produce; else why it is taken for corrupt: a reading more than one
        stroke beyond the model's travel (1e300 m, 1 m on a 30 µm stage), or an applied voltage more than a tenth
        of the range beyond the limits (the amplifier cannot apply it)."""
        far = self._beyond_travel("position", y)
        if far:
            return far
        lim = self.limits
        margin = 0.1 * (lim.v_max - lim.v_min)
        if u is not None and math.isfinite(u) and not lim.v_min - margin <= u <= lim.v_max + margin:
            return f"applied voltage {u:.6g} V is beyond the limits {lim.v_min:g}..{lim.v_max:g} V"
        return ""

    def plausible_reference(self, r: float) -> str:
        """'' for a reference a user could mean; else why it is taken for corrupt: more than one stroke beyond the
        travel, as :meth:`plausible` judges states (a 1e300 m reference drove the command to the range's end)."""
        return self._beyond_travel("reference", r)

    def plausible_velocity(self, v: float) -> str:
        """'' for a reference velocity (m/s) a stage could follow; else why it is taken for corrupt: faster than the
        whole travel in one sample (a 600 Hz full-stroke sine at 2 kHz). A 62.8 "m/s" (µm/s sent unscaled) or a
        1e300 was extrapolated into a reference 1e297 m away and drove every command to the rail."""
        if not math.isfinite(v):
            return f"reference velocity {v} m/s is not finite"
        if self.stroke is not None:
            lim = (self.stroke[1] - self.stroke[0]) * self.rate
            if abs(v) > lim:
                return f"reference velocity {v:.6g} m/s is faster than the whole travel in one sample ({lim:.3g} m/s)"
        return ""

    def _beyond_travel(self, what: str, v: float) -> str:
        """Why ``v`` (m) lies more than one stroke beyond the model's travel, or '' (also without a travel)."""
        if self.stroke is not None:
            lo, hi = self.stroke
            span = hi - lo
            if not lo - span <= v <= hi + span:
                return f"{what} {v:.6g} m is beyond the stage's travel ({lo:.3g}..{hi:.3g} m) by more than its stroke"
        return ""

    def reachable(self, r: float) -> bool:
        """False for a reference beyond the model's rest travel at the limits (the stage cannot hold it)."""
        return self.stroke is None or self.stroke[0] <= r <= self.stroke[1]

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


def _reference(spec: str, profile: str, stroke: tuple[float, float] | None,
               limits: CommandLimits) -> Reference | None:
    """The internal reference of a spec: on the PEA's stroke as documented, on the model's own ``stroke`` (its rest
    displacement at ``v_min`` and ``v_max``) for any other profile — the GMA's ±20 µm holds no 5–25 µm sine."""
    if not spec:
        return None
    if profile == "pea":
        ref = parse_reference(spec)
    elif stroke is None:
        raise ControlError(f"reference {spec!r}: the model has no finite, increasing rest displacement over "
                           f"v_min..v_max ({limits.v_min:g}..{limits.v_max:g} V) to place it on; check the model")
    else:
        ref = parse_reference(spec, stroke=stroke)
    if stroke is not None:  # sine:5:1e300 was taken and drove the commands to the range's ends
        lo, hi = ref.extent()
        tol = 0.1 * (stroke[1] - stroke[0])
        if lo < stroke[0] - tol or hi > stroke[1] + tol:
            raise ControlError(f"reference {spec!r} spans {lo * 1e6:.4g}..{hi * 1e6:.4g} µm, beyond the model's "
                               f"travel {stroke[0] * 1e6:.4g}..{stroke[1] * 1e6:.4g} µm at the limits (by more than "
                               "a tenth of it): the stage cannot follow it")
    return ref


#: A model is refused for limits reaching more than this many times the largest voltage it was identified at.
REACH_FACTOR = 10.0


def _same_actuator(model: MBWParams, limits: CommandLimits) -> None:
    """Refuse a model identified on a far smaller voltage range than the limits drive: another actuator's (a GMA
    model fitted on −4.8…1.4 V ran DPPC on the PEA's 0–150 V with only a divergence warning). ``u_scale`` is the
    largest |u| of the identification record over 10 model units (:func:`hyst_model.models.data_config`)."""
    reach = max(abs(limits.v_min), abs(limits.v_max))
    ident = 10.0 * model.u_scale
    if ident > 0 and reach > REACH_FACTOR * ident:
        raise ControlError(f"the model was identified up to about {ident:.3g} V (u_scale {model.u_scale:g} V per "
                           f"unit) but the limits reach {reach:g} V, {reach / ident:.0f}× beyond it: a model of "
                           "another actuator or range? Identify on the range the controller drives, or narrow "
                           "v_min/v_max")


def read_settings(get: Callable[[str], Any], effect_keys: tuple[str, ...]) -> ControllerSettings:
    """The settings the node's parameters give, every check made; ``get(name)`` is a parameter's value.

    Raises :class:`~hyst_control.errors.ControlError` (or ValueError) with the reason a parameter set is refused:
    an unknown algorithm or policy, a model that is not an MBW, a model identified at another rate, gains unstable
    against an identified resonance under ``refuse``, a model that diverges where it would run open loop, a law
    that cannot be built. ``effect_keys``: the dotted effect parameters declared (``creep.gain`` ...).
    """
    f = float
    alg = str(get("algorithm"))
    if alg not in ALGORITHMS:
        raise ControlError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {alg!r}")
    if str(get("model.base")) != "mbw":
        raise ControlError("the controllers invert the MBW model: model.base must be 'mbw'")
    mdt, rate = f(get("model.dt")), f(get("rate"))
    if mdt > 0 and not same_rate(mdt, rate):
        raise ControlError(f"the model was identified at dt = {mdt:g} s but rate = {rate:g} Hz: the MBW recursion "
                           f"is per sample, so set rate:={1.0 / mdt:g} (or refit the model at this rate)")
    profile = str(get("profile")).strip().lower()
    check_range(profile, f(get("v_min")), f(get("v_max")))  # ConfigError (a ValueError): refused with it
    init = str(get("dmrac.initial")).lower()
    if init != "model" and init not in TABLE53:
        raise ControlError("dmrac.initial must be model, cs0, cs1, cs2 or cs3")
    gains = {a: cls(**{n: get(f"{a}.{n}") for n in spec}) for a, (cls, spec) in GAINS.items()}
    model = check_model(MBWParams(**{k: f(get(f"model.{k}")) for k in MODEL_KEYS}))  # whatever runs now
    effects = tuple(str(e) for e in (get("model.effects") or ()) if str(e))  # [""] = none (ROS types lists)
    evals = tuple((k, get(f"model.{k}")) for k in effect_keys if k.split(".")[0] in effects)
    policy = str(get("stability.policy"))
    if policy not in POLICIES:
        raise ControlError(f"stability.policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    comp = plan_compensation(model, effects, dict(evals), dict(evals), 1.0 / rate)
    limits = CommandLimits(f(get("v_min")), f(get("v_max")), f(get("slew_max")), f(get("v_safe")))
    _same_actuator(model, limits)
    divergence = model_divergence(alg, model, comp, limits, 1.0 / rate)  # ControlError: refused
    stroke = model.rest_range(limits.v_min, limits.v_max)  # the reach, and the plausible readings
    # checked as the compensation will run it (a mode it inverts is left only as a model error)
    res = identified_resonance(effects, dict(evals), comp)
    notch = get("stability.notch")
    if not isinstance(notch, bool):
        raise ControlError(f"stability.notch must be true or false, got {notch!r}")
    stab = cached_guard(alg, gains.get(alg), model, 1.0 / rate, res, policy, f(get("stability.gain_margin")),
                        (f(get("v_min")), f(get("v_max"))), notch)  # StabilityError (a ControlError) = rejected
    s = ControllerSettings(
        algorithm=alg, rate=rate, limits=limits,
        watchdog_periods=int(get("watchdog_periods")), state_decimation=int(get("state_decimation")),
        dmrac_initial=init, model=model,
        reference=_reference(str(get("reference")), profile, stroke, limits), stability=stab,
        effects=effects, effect_values=evals, gain_sets=tuple(gains.items()), divergence=divergence,
        stroke=stroke, safe_ramp_rate=f(get("safe_ramp_rate")))
    make_controller(alg, model, 1.0 / s.rate, s.limits, s.gains(alg), init, s.compensation())  # checks all
    return s
