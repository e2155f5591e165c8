"""The one range-and-slew limiter: the last thing between a command and the amplifier, in the controller, the
simulated amplifier and the driver alike.

:func:`limit_step` is the core every limiter in hyst goes through; what differs between its three users is only
what a command *is* before it reaches it, so each keeps a thin wrapper that says so:

* the controller (:meth:`CommandLimits.apply`, here): a law's raw output. NaN holds the previous command (or
  ``v_safe`` before there is one), ±inf saturates, and a previous command more than one step outside a narrowed
  range counts as the nearest range edge (the range wins; the command approaches from the edge at full slew,
  as the driver brings its output into a new window at once). The controllers feed the *limited* command back
  into their own memory (u_{k-1} in (4.12), (5.23)), which is their anti-windup.
* the simulated amplifier (``hyst_sim.plant_kernel``, :func:`limit_step` compiled by numba): any non-finite
  command holds the voltage applied one sample earlier, flagged, as an amplifier ignores a corrupted setpoint.
* the driver (``hyst_driver.safety.VoltageLimiter``): requests are checked (non-finite and "huge" ones rejected)
  before they become a target, the output lives on the wire's integer grid and always inside the window, and
  each step is further confined to the in-flight envelope judged against the voltage the device reports it
  applies. Its core step is :func:`limit_step` on grid indices (integers pass through unchanged).

Keeping one core and three wrappers, rather than one class, is deliberate: the three differ in what they must
do with a bad command (saturate it, hold it, reject it) and the driver's property-tested envelope needs state
that the other two must not have.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError

__all__ = ["CommandLimits", "limit_step", "beyond_span", "LIMIT_RANGE", "LIMIT_SLEW", "LIMIT_NONFINITE"]

#: Flag bits returned by :func:`limit_step`: range clipped, slew limited, NaN replaced by the previous value.
LIMIT_RANGE, LIMIT_SLEW, LIMIT_NONFINITE = 1, 2, 4


def beyond_span(v: float, v_min: float, v_max: float) -> bool:
    """True for a command more than one range span outside ``[v_min, v_max]`` (and for NaN): a corrupted or
    unit-confused request (150000 meant as mV) that the driver and the sim reject and hold, instead of clipping it
    to full scale as they clip one just outside."""
    span = v_max - v_min
    return not (v_min - span <= v <= v_max + span)


def limit_step(v, v_min, v_max, v_prev, max_step):
    """Limit one command to a range and to one slew step from the previous output.

    Plain arithmetic and comparisons only, so that numba compiles it for the sim's per-sample loop and integer
    grid indices (the driver) stay integers.

    Parameters
    ----------
    v : float or int
        Command (V). NaN holds ``v_prev``; ±inf saturates at the range.
    v_min, v_max : float or int
        Allowed range (V).
    v_prev : float or int
        Output one sample earlier (V), finite.
    max_step : float or int
        Largest change per sample (V), ``slew_max * dt``; ``inf`` disables the slew limit.

    Returns
    -------
    v_out : float or int
        Inside ``[v_min, v_max]`` and, when ``v_prev`` lies within ``max_step`` of the range, within
        ``max_step`` of it. Order: range, slew relative to ``v_prev``, then the range again, so that the output
        is inside the range even when ``v_prev`` is not (e.g. right after the range was narrowed).
    flags : int
        :data:`LIMIT_RANGE` | :data:`LIMIT_SLEW` | :data:`LIMIT_NONFINITE` (0: passed unchanged).
    """
    flags = 0
    if v != v:  # NaN: hold what was applied, never pass a NaN to an amplifier
        v = v_prev
        flags = LIMIT_NONFINITE
    else:
        if v < v_min:
            v = v_min
            flags |= LIMIT_RANGE
        elif v > v_max:
            v = v_max
            flags |= LIMIT_RANGE
        if v > v_prev + max_step:
            v = v_prev + max_step
            flags |= LIMIT_SLEW
        elif v < v_prev - max_step:
            v = v_prev - max_step
            flags |= LIMIT_SLEW
    if v < v_min:
        v = v_min
        flags |= LIMIT_RANGE
    elif v > v_max:
        v = v_max
        flags |= LIMIT_RANGE
    return v, flags


@dataclass(frozen=True)
class CommandLimits:
    """Range and slew limits of a command (SI: V, V/s), as every algorithm's output sees them.

    Attributes
    ----------
    v_min, v_max : float
        Command range (V). The PEA amplifier takes 0–150 V, the GMA driver ±5 V (:mod:`hyst_common.profiles`).
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
        """Limit one command (:func:`limit_step` with the controller's reading of a bad command).

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
        lo, hi = self.v_min, self.v_max
        if u_prev != u_prev:  # no previous command: the range alone, and NaN becomes v_safe
            return limit_step(self.v_safe if u != u else u, lo, hi, self.v_safe, math.inf)[0]
        step = math.inf if self.slew_max == math.inf else self.slew_max * dt
        if u_prev < lo - step:  # more than a step outside a narrowed range: approach it from its edge
            u_prev = lo
        elif u_prev > hi + step:
            u_prev = hi
        return limit_step(u, lo, hi, u_prev, step)[0]
