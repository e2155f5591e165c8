"""The controller node's settings as plain values (no rclpy): the gain table every ``<algorithm>.<name>`` parameter
is declared, validated and applied from, the frozen :class:`ControllerSettings` swapped whole on a parameter
change, and the profile's default stage model."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from hyst_common.limits import CommandLimits
from hyst_model.core import PARAM_NAMES, MBWParams, pea_default, stage_model

from .compensation import Compensation, plan_compensation
from .dmrac import DMRACGains
from .dppc import DPPCGains
from .pid import PIDGains
from .reference import Reference
from .stability import StabilityVerdict, guard

__all__ = ["ControllerSettings", "GAINS", "MODEL_KEYS", "profile_model", "cached_guard"]

_F = float
# name: (default, lo, hi, description) for every gain; one table feeds declaration, validation and application.
GAINS = {
    "dppc": (DPPCGains, {
        "lambda0": (20e-6, 1e-9, 1e-3, "initial funnel half-width λ0 (m), Table 4.2: 20 µm"),
        "lambda_inf": (0.4e-6, 1e-10, 1e-4, "final funnel half-width λ∞ (m), Table 4.2: 0.4 µm"),
        "omega": (0.01, 1e-6, 0.999, "funnel decay per sample ω (4.7)"),
        "chi": (0.1, 1e-3, 0.999, "error contraction χ (4.11); larger = gentler, more robust"),
        "h_lower": (1.0, 0.01, 100.0, "lower funnel factor h̲ (4.8)"),
        "h_upper": (1.0, 0.01, 100.0, "upper funnel factor h̄ (4.8)"),
        "funnel_margin": (0.9, 0.1, 0.99, "out-of-funnel re-initialisation margin ρ"),
        "ki": (0.0, 0.0, 0.99, "integral of the error on the target (beyond thesis; 0 = off)"),
        "zeta0": (1e-3, 1e-9, 1.0, "lower bound on μ (Assumption 4.1)"),
        "exact_rate": (True, None, None, "invert with the input rate (true) or the reference rate r_u (4.3)")}),
    "dmrac": (DMRACGains, {
        "kappa1": (0.01, 1e-6, 1.99, "adaptation gain κ1 of ζ1, ψ1, α1 (5.12)-(5.17)"),
        "kappa2": (0.01, 0.0, 1.99, "adaptation gain κ2 of ζ2, ψ2, α2"),
        "a_m": (0.1, -0.99, 0.99, "reference-model pole a_m (5.3) = closed-loop error pole"),
        "zeta0": (1e-3, 1e-9, 1.0, "projection bound ζ0 (5.12b)"),
        "varrho": (1e-4, 1e-9, 1.0, "projection margin ϱ (5.16b)"),
        "theta_max": (10.0, 0.01, 1e3, "box on every estimate (model units)"),
        "deadzone": (0.0, 0.0, 1e-6, "no adaptation below this estimation error (m)"),
        "exact_rate": (True, None, None, "invert with the input rate (true) or r_u (5.4)")}),
    "pid": (PIDGains, {
        "kp": (1.0e6, 0.0, 1e9, "proportional gain (V/m)"),
        "ki": (8.0e9, 0.0, 1e13, "integral gain (V/(m s))"),
        "kd": (0.0, 0.0, 1e6, "derivative gain (V s/m)"),
        "t_filter": (2e-3, 1e-6, 1.0, "derivative filter time constant (s)"),
        "t_track": (5e-3, 1e-6, 10.0, "anti-windup back-calculation time constant (s)")}),
}
MODEL_KEYS = PARAM_NAMES + ("offset", "u_scale", "y_scale")
# The check is a few tens of ms; the on-set callback and the post-set callback both build the settings.
cached_guard = lru_cache(maxsize=64)(guard)


@dataclass(frozen=True)
class ControllerSettings:
    """Every node parameter as plain values; swapped as a whole on a parameter change."""

    algorithm: str
    rate: float
    limits: CommandLimits
    watchdog_periods: int
    state_decimation: int
    dppc: DPPCGains
    dmrac: DMRACGains
    dmrac_initial: str
    pid: PIDGains
    model: MBWParams
    reference: Reference | None = None
    #: The params file's effects (innermost first) and their parameters/configuration, dotted (``creep.gain``).
    effects: tuple = ()
    effect_values: tuple = ()
    stability: StabilityVerdict | None = None

    def compensation(self) -> Compensation:
        """A fresh compensation (its effects keep per-run state) for the model's effects."""
        vals = dict(self.effect_values)
        return plan_compensation(self.model, self.effects, vals, vals, 1.0 / self.rate)

    def gains(self, algorithm: str):
        """The gains that run: derated by the stability check when the resonance demands it."""
        st = self.stability
        if st is not None and st.algorithm == algorithm:
            return st.gains
        return getattr(self, algorithm) if algorithm in GAINS else None


def profile_model(profile: str) -> MBWParams:
    """The default stage model for a profile (:func:`hyst_model.core.stage_model`, as the sim's); an unknown
    profile falls back to the embedded default (the profile's limits report the bad name)."""
    try:
        return stage_model(profile)
    except ValueError:
        return pea_default()
