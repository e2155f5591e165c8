"""Command and slew limits applied to every algorithm's output.

The limiter is the last thing between a control law and the amplifier: whatever the law computes (including
NaN or ±inf after a numerical accident), the command that leaves is finite, inside ``[v_min, v_max]`` and
within ``slew_max·dt`` of the previous command. The controllers feed the *limited* command back into their own
memory (u_{k-1} in (4.12), (5.23)), which is their anti-windup.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError

__all__ = ["CommandLimits", "PEA_LIMITS", "GMA_LIMITS"]


@dataclass(frozen=True)
class CommandLimits:
    """Range and slew limits of the command (SI: V, V/s).

    Attributes
    ----------
    v_min, v_max : float
        Command range (V). The PEA amplifier takes 0–150 V, the GMA driver ±5 V.
    slew_max : float
        Largest |du/dt| (V/s); ``inf`` disables the slew limit.
    v_safe : float
        Output held when the law produced NaN before any valid command existed, and by the node's watchdog.
    """

    v_min: float = 0.0
    v_max: float = 150.0
    slew_max: float = math.inf
    v_safe: float = 0.0

    def __post_init__(self) -> None:
        vals = (self.v_min, self.v_max, self.v_safe)
        if not all(math.isfinite(v) for v in vals):
            raise ConfigError("v_min, v_max and v_safe must be finite")
        if not self.v_min < self.v_max:
            raise ConfigError(f"v_min ({self.v_min}) must be below v_max ({self.v_max})")
        if not self.v_min <= self.v_safe <= self.v_max:
            raise ConfigError(f"v_safe ({self.v_safe}) must lie in [v_min, v_max]")
        if not self.slew_max > 0 or math.isnan(self.slew_max):
            raise ConfigError("slew_max must be positive (inf disables it)")

    def apply(self, u: float, u_prev: float, dt: float) -> float:
        """Limit one command.

        Parameters
        ----------
        u : float
            Raw command from a law (V); NaN holds ``u_prev``; ±inf saturates.
        u_prev : float
            Previous command actually sent (V); NaN means there is none (no slew limit, NaN → ``v_safe``).
        dt : float
            Sample period (s).

        Returns
        -------
        float
            Finite command in ``[v_min, v_max]`` and, when ``u_prev`` is inside the range, within
            ``slew_max·dt`` of it.
        """
        have_prev = u_prev == u_prev  # not NaN
        if u != u:  # NaN: hold what we had — never pass a NaN to an amplifier
            u = u_prev if have_prev else self.v_safe
        lo, hi = self.v_min, self.v_max
        if have_prev and self.slew_max != math.inf:
            step = self.slew_max * dt
            lo = max(lo, u_prev - step)
            hi = min(hi, u_prev + step)
            if lo > hi:  # previous command outside the range: range wins, approach it at full slew
                lo, hi = (self.v_min, min(self.v_max, self.v_min + step)) if u_prev < self.v_min else \
                    (max(self.v_min, self.v_max - step), self.v_max)
        return min(max(u, lo), hi)


#: PEA amplifier 0–150 V (thesis 4.3.1), slew 1e5 V/s like the sim/driver profile (hyst_sim.profiles.PEA).
PEA_LIMITS = CommandLimits(0.0, 150.0, 1.0e5, 0.0)
#: GMA driver input ±5 V (thesis Table 5.1).
GMA_LIMITS = CommandLimits(-5.0, 5.0, 1.0e4, 0.0)
