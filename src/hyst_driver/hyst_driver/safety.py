"""Voltage safety: the one place the amplifier limits are enforced before any byte leaves the driver.

Pure (no I/O, no clock): callers pass time steps. Invariants, proven by the property test
``test/test_safety.py`` over random command streams including NaN, ±inf and huge values:

1. every output lies in ``[v_min, v_max]`` — after rounding to the wire grid (:attr:`Limits.quantum`, 1 µV),
   so the decoded frame is inside the window too;
2. consecutive outputs differ by at most ``slew_max · dt`` with ``dt`` capped at one device sample
   (``dt_max``): a long pause does not license a step, since the amplifier would see it as one;
3. non-finite requests, and finite ones further than one window span outside the window ("huge": a corrupted
   or unit-confused command, e.g. 150000 meant as mV), are *rejected*: the previous target is kept. Requests
   just outside the window are *clipped* (ordinary saturation) and counted.

When the limits change so that the present output falls outside the new window, the output moves into the
window at once (invariant 1 wins over 2).

Each step's range-and-slew arithmetic is the one core every hyst limiter shares,
:func:`hyst_common.limits.limit_step` (on integer grid indices); what is the driver's own, and why it is a wrapper
rather than the controller's or the sim's limiter, is everything around it: requests are checked before they
become a target, the output is quantised to the wire, a step is credited at most one device sample, and the
in-flight envelope is judged against the voltage the device reports it applies.

Invariant 2 bounds consecutive *writes*; the amplifier, though, applies the last setpoint it has received at
each of its own samples, so two writes delivered within one device sample make one double step (measured: 20.4–
26.5 V against a 20 V-per-sample limit with three CPU hogs beside the driver). A host clock cannot prevent that;
the device's read-back can. The limiter therefore also keeps the **in-flight envelope** (:meth:`sent`,
:meth:`observe`): the set of voltages the device may be applying now or at any later sample — the last
confirmed read-back and every write not yet shown superseded — and each write must lie within
``slew_max · dt_max`` (one device sample) of *every* member. Property (``test_safety.py``, any interleaving of
writes, device samples and read-backs):

4. the voltage the device applies never changes by more than ``slew_max · dt_max`` between two of its samples
   and never leaves ``[v_min, v_max]`` (once the first write is applied).

A read-back of value ``v`` proves that the device received every write up to the first in-flight one equal to
``v`` (the link is FIFO and the device applies the last one received), so those leave the set. When nothing
admissible is left (the device lags behind), the limiter *holds*: :attr:`VoltageLimiter.hold` is True and nothing
may be written until a read-back narrows the set, which paces writes to the device's own samples.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from functools import cached_property

from hyst_common.limits import LIMIT_SLEW, beyond_span, limit_step

from .errors import ConfigError

__all__ = ["Limits", "VoltageLimiter", "CommandWatchdog", "LimiterCounts"]


@dataclass(frozen=True)
class Limits:
    """Voltage window, slew limit and safe voltage of the amplifier input.

    Attributes
    ----------
    v_min, v_max : float
        Window (V), ``v_min < v_max``.
    slew_max : float
        Largest rate of change (V/s), > 0.
    v_safe : float
        Voltage the driver ramps to when commands stop and on shutdown (V), inside the window.
    dt_max : float
        Longest time step credited to the slew limit (s): one device sample period.
    quantum : float
        Wire resolution (V); outputs are multiples of it.
    safe_ramp_rate : float
        Rate (V/s) of ramps to ``v_safe`` (watchdog, shutdown), never above ``slew_max``; ``inf`` = ``slew_max``.
    flight_max : float
        Longest time (s) between writing a setpoint and the device applying it (FIFO link, the device reads its
        input every sample). Only used to forget a write that no read-back ever showed (lost on the wire or
        refused by the device): after two read-backs of samples taken ``flight_max`` after it, it can no longer
        arrive. Generous (1 s: a host stalls for hundreds of ms at load 14), because a write forgotten too early
        could still arrive, and the only cost of a long one is a slower recovery from a lost write.
    """

    v_min: float
    v_max: float
    slew_max: float
    v_safe: float
    dt_max: float = 1e-3
    quantum: float = 1e-6
    safe_ramp_rate: float = math.inf
    flight_max: float = 1.0

    def __post_init__(self) -> None:
        vals = (self.v_min, self.v_max, self.slew_max, self.v_safe, self.dt_max, self.quantum)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            raise ConfigError(f"limits must be finite numbers: {self}")
        if not self.v_min < self.v_max:
            raise ConfigError(f"v_min ({self.v_min} V) must be below v_max ({self.v_max} V)")
        if not self.v_min <= self.v_safe <= self.v_max:
            raise ConfigError(f"v_safe ({self.v_safe} V) must lie in [v_min, v_max] = [{self.v_min}, {self.v_max}] V")
        if not self.slew_max > 0 or not self.dt_max > 0 or not self.quantum > 0:
            raise ConfigError("slew_max, dt_max and quantum must be positive")
        if not (isinstance(self.flight_max, (int, float)) and self.flight_max > 0):
            raise ConfigError(f"flight_max must be positive, got {self.flight_max}")
        if not self.safe_ramp_rate > 0:
            raise ConfigError(f"safe_ramp_rate must be positive (inf = slew_max), got {self.safe_ramp_rate}")
        if self.hi_q < self.lo_q:
            raise ConfigError(f"window [{self.v_min}, {self.v_max}] V holds no multiple of {self.quantum} V")

    def to_volts(self, k: int) -> float:
        """Voltage of grid index ``k``; divides by 1/quantum when that is an integer (1e6 → exact decimals)."""
        inv = round(1.0 / self.quantum)
        return k / inv if abs(inv * self.quantum - 1.0) < 1e-12 else k * self.quantum

    @cached_property  # frozen: computed once per Limits (the limiter asks every sample)
    def lo_q(self) -> int:
        """Smallest grid index whose voltage is ≥ v_min."""
        k = round(self.v_min / self.quantum)
        return k + 1 if self.to_volts(k) < self.v_min else k

    @cached_property
    def hi_q(self) -> int:
        """Largest grid index whose voltage is ≤ v_max."""
        k = round(self.v_max / self.quantum)
        return k - 1 if self.to_volts(k) > self.v_max else k

    def is_huge(self, v: float) -> bool:
        """True for requests more than one window span outside the window (rejected, not clipped)."""
        return beyond_span(v, self.v_min, self.v_max)


@dataclass
class LimiterCounts:
    """Running counts for diagnostics."""

    accepted: int = 0
    clipped: int = 0
    rejected: int = 0
    slew_limited: int = 0
    held: int = 0
    """Steps that found no admissible voltage (the device had not yet confirmed enough): nothing written."""
    expired: int = 0
    """In-flight writes forgotten after ``flight_max`` without a read-back showing them (lost or refused)."""
    unexplained: int = 0
    """Read-backs outside every voltage the limiter sent or saw confirmed (a device reset, a corrupted line)."""


class VoltageLimiter:
    """Stateful limiter: turns requested voltages into safe output voltages.

    Parameters
    ----------
    limits : Limits
    v0 : float, optional
        Present output (e.g. the voltage the device reports after connecting); ``v_safe`` if omitted.
    track_flight : bool
        Keep the in-flight envelope (invariant 4; the caller reports writes with :meth:`sent` and read-backs
        with :meth:`observe`). False: every output counts as applied the moment it is computed (a plant stepped
        in the same thread; the tests of invariants 1–3 alone).
    """

    #: Longest time step (s) credited to a ramp to ``v_safe`` (keeps a stalled host from licensing a jump).
    RAMP_DT_MAX = 0.1

    #: Most writes kept in flight; beyond it the limiter holds (a device that confirms nothing gets nothing new).
    FLIGHT_MAX_LEN = 256

    def __init__(self, limits: Limits, v0: float | None = None, *, track_flight: bool = True) -> None:
        self._limits = limits
        self._k = self._clamp_k(self._to_k(limits.v_safe if v0 is None else v0))
        self._target_k = self._k
        self._safe = False
        self._ramp_start = False  # a ramp to v_safe was requested and has not stepped yet
        self.counts = LimiterCounts()
        #: True when the last :meth:`step` found no admissible voltage: the caller must not write.
        self.hold = False
        self.track_flight = track_flight
        #: Write → applied delays (s): a write's time to the sample time of the read-back that first showed it
        #: applied, newest 2000. The whole downstream path (host write, serial link, the device's next sample),
        #: measured by the device's own read-back: a link that delays commands shows here, not in the counters.
        self.apply_delays: deque[float] = deque(maxlen=2000)
        self._reset_flight(self._k)

    # ------------------------------------------------------------ state
    @property
    def limits(self) -> Limits:
        return self._limits

    @property
    def value(self) -> float:
        """Present output (V), on the wire grid."""
        return self._limits.to_volts(self._k)

    @property
    def target(self) -> float:
        """Voltage the output is moving to (V)."""
        return self._limits.to_volts(self._target_k)

    @property
    def settled(self) -> bool:
        """True when the output has reached the target."""
        return self._k == self._target_k

    def _to_k(self, v: float) -> int:
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            return round(self._limits.v_safe / self._limits.quantum)
        v = min(max(v, self._limits.v_min - 1.0), self._limits.v_max + 1.0)  # no overflow for 1e308
        return round(v / self._limits.quantum)

    def _clamp_k(self, k: int) -> int:
        return min(max(k, self._limits.lo_q), self._limits.hi_q)

    def reset(self, v: float) -> None:
        """Re-seed the output with what the device actually applies (after a (re)connect).

        Non-finite ``v`` seeds ``v_safe``; values outside the window are brought inside it. The target becomes
        the output, so nothing moves until the next request. The in-flight envelope restarts from ``v`` as the
        device reported it (not clamped: the first write is judged from where the amplifier really is).
        """
        self._k = self._clamp_k(self._to_k(v))
        self._target_k = self._k
        # the reported value itself, not _to_k's overflow guard (which clamps to v_min - 1: a device at 0 V under
        # v_min = 10 V was taken to be at 9 V, and a 29 V first step passed)
        finite = isinstance(v, (int, float)) and math.isfinite(v)
        self._reset_flight(round(v / self._limits.quantum) if finite else self._k)
        if self._base_k != self._k:  # reported outside the window: moving into it beats the slew limit
            self._jump = True

    def set_limits(self, limits: Limits) -> None:
        """Swap the limits; output and target are brought into the new window at once."""
        self._limits = limits
        k = self._clamp_k(self._k)
        self._jump = self._jump or k != self._k  # invariant 1 wins: the next write may leave the envelope
        self._k = k
        self._target_k = self._clamp_k(self._target_k)

    # ------------------------------------------------------------ in-flight envelope
    def _reset_flight(self, k: int) -> None:
        self._base_k = k                                   # last confirmed applied voltage (grid index)
        self._flight: deque[list] = deque()                # [grid index, write time], oldest first
        self._obs_t = -math.inf                            # sample time of the previous read-back
        self._odd: int | None = None                       # last unexplained read-back, awaiting a second
        self._jump = False

    @property
    def in_flight(self) -> tuple[float, ...]:
        """Voltages written that no read-back has yet shown superseded (V), oldest first."""
        return tuple(self._limits.to_volts(k) for k, _ in self._flight)

    @property
    def confirmed(self) -> float:
        """Last applied voltage a read-back confirmed (V)."""
        return self._limits.to_volts(self._base_k)

    def sent(self, t: float) -> None:
        """The present output is being written at time ``t`` (s, the caller's monotonic clock).

        Call it *before* the bytes go out: a write that fails half-way may still have reached the device.
        """
        self._jump = False
        if self._flight and self._flight[-1][0] == self._k:
            self._flight[-1][1] = t  # the same voltage again (keepalive): one member, the later time
        elif self._flight or self._k != self._base_k:
            self._flight.append([self._k, t])

    def observe(self, v: float, t_sample: float) -> None:
        """A read-back: the device applied ``v`` (V) at its sample taken at ``t_sample`` (s, caller's clock).

        ``t_sample`` must not be later than the true sample time by more than a few device samples (a device
        clock mapped to the host's, or the time the poll that asked for it was sent); ``-inf`` when unknown
        (then it forgets nothing).
        """
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            return
        k = round(v / self._limits.quantum)
        if k == self._base_k:
            self._odd = None  # an unexplained value must be read twice in a row to be believed
        else:
            i = next((j for j, (kf, _) in enumerate(self._flight) if kf == k), -1)
            if i >= 0:  # FIFO: every write up to this one has arrived; only this one's value is left of them
                if math.isfinite(t_sample):
                    self.apply_delays.append(t_sample - self._flight[i][1])
                for _ in range(i + 1):
                    self._flight.popleft()
                self._base_k, self._odd = k, None
            elif self._odd == k:  # twice in a row: the device really is there (e.g. it reset itself)
                self._base_k, self._odd = k, None
                kc = self._clamp_k(k)  # go on from there, as after a reconnect (the old output is history)
                self._jump = self._jump or kc != k
                self._k = kc
            else:
                self.counts.unexplained += 1
                self._odd = k
        # Two read-backs of samples taken flight_max after a write: it has arrived and been superseded or
        # refused; it can no longer be applied (two, because a polled device may answer just before its next
        # sample applies what it has received).
        cutoff = min(self._obs_t, t_sample) - self._limits.flight_max
        while self._flight and self._flight[0][1] <= cutoff:
            self._flight.popleft()
            self.counts.expired += 1
        self._obs_t = max(self._obs_t, t_sample)

    def _envelope(self) -> tuple[int, int]:
        """Grid indices admissible for the next write: within one device sample's slew of every voltage the
        device may be applying (empty when lo > hi)."""
        lo = hi = self._base_k
        for kf, _ in self._flight:
            lo, hi = min(lo, kf), max(hi, kf)
        lim = self._limits
        step = math.floor(lim.slew_max * lim.dt_max / lim.quantum)
        return hi - step, lo + step

    # ------------------------------------------------------------ requests
    def request(self, v: float) -> bool:
        """Set a new target. Returns False (and keeps the old target) for non-finite or huge requests."""
        lim = self._limits
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or lim.is_huge(v):
            self.counts.rejected += 1
            return False
        k = round(v / lim.quantum)
        kc = self._clamp_k(k)
        if kc != k:
            self.counts.clipped += 1
        self.counts.accepted += 1
        self._target_k = kc
        self._safe = False
        return True

    def request_safe(self) -> None:
        """Target ``v_safe`` (watchdog, shutdown), approached at ``min(slew_max, safe_ramp_rate)``; the ramp's
        first step is credited one sample period at most (the time since the last write was spent holding)."""
        self._target_k = self._clamp_k(round(self._limits.v_safe / self._limits.quantum))
        self._ramp_start = self._ramp_start or not self._safe
        self._safe = True

    def step(self, dt: float) -> float:
        """Advance the output toward the target by at most ``slew_max · min(dt, dt_max)``, within the in-flight
        envelope; return it (V). When no voltage is admissible :attr:`hold` becomes True, the output stays and
        must not be written (until a read-back arrives: :meth:`observe`).

        A non-finite or negative ``dt`` counts as zero (the output holds).
        """
        lim = self._limits
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            dt = 0.0
        step = lim.slew_max * min(dt, lim.dt_max)  # the hard limit: what the amplifier sees per sample
        # the gentler ramp follows real time (a late write catches up), never above the hard limit
        if self._safe and math.isfinite(lim.safe_ramp_rate):
            # a ramp that starts now has not ramped over the keepalive's 0.1 s before it: that credit made its
            # first step 10 V at 100 V/s, the steps after it 0.1-0.3 V
            credit = min(dt, lim.dt_max) if self._ramp_start else min(dt, self.RAMP_DT_MAX)
            step = min(step, lim.safe_ramp_rate * credit)
        if dt > 0:
            self._ramp_start = False
        max_dk = math.floor(step / lim.quantum)
        # The one range-and-slew core (hyst_common.limits) on grid indices: target and output are always in the
        # window here (request, reset and set_limits bring them in), so it is the slew step alone.
        k, flags = limit_step(self._target_k, lim.lo_q, lim.hi_q, self._k, max_dk)
        if flags & LIMIT_SLEW:
            self.counts.slew_limited += 1
        self.hold = False
        if not self.track_flight:
            self._k = k
            return self.value
        if self._jump:  # the window moved past the output: write the output brought into it (invariant 1 wins)
            return self.value
        lo, hi = self._envelope()
        lo, hi = max(lo, lim.lo_q, self._k - max_dk), min(hi, lim.hi_q, self._k + max_dk)
        # An unexplained read-back pending: the amplifier may have reset itself with the link up; until a second
        # read-back settles it, even a keepalive of the old setpoint could be a full-window step.
        if len(self._flight) >= self.FLIGHT_MAX_LEN or lo > hi or self._odd is not None:
            self.hold = True  # nothing admissible until the device confirms more: write nothing
            self.counts.held += 1
            return self.value
        self._k = min(max(k, lo), hi)
        return self.value

    def update(self, v: float, dt: float) -> float:
        """``request(v)`` then ``step(dt)``: one command in, one safe output out."""
        self.request(v)
        return self.step(dt)


@dataclass
class CommandWatchdog:
    """Expires when no command has arrived for ``timeout`` seconds (times from the caller's monotonic clock).

    Starts expired: until the first command arrives the driver holds or ramps to ``v_safe``.
    """

    timeout: float
    last: float = field(default=-math.inf)

    def feed(self, now: float) -> None:
        """A command arrived at ``now``."""
        self.last = now

    def expired(self, now: float) -> bool:
        return now - self.last > self.timeout
