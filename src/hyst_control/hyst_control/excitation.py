"""Open-loop voltage excitations for identification (issue 11, Build 3): numerical core, numpy only.

One excitation is a concatenation of parts, each starting and ending at the rest voltage, separated by holds:

``steps``      random levels (seeded) reached by a raised-cosine ramp of ``step_rise`` s and held ``hold`` s each
               — creep/settling, static loop points
``sines``      whole periods of a sine at several amplitudes (fractions of the range) — major and minor loops
``triangles``  the same with triangles (constant rate: rate-independence check)
``multisine``  log-spaced frequencies, random phases (seeded), faded in and out — dynamics and memory
``sweep``      a linear chirp ``f_lo`` → ``f_hi``, faded in and out — rate dependence, resonance
``noise``      seeded Gaussian noise band-limited to ``f_lo`` … ``f_hi`` (FFT mask), faded in and out — what tells
               a stage mode from a delay and creep from drift (no tone to hide behind); not in the default parts

The rest voltage is 0 V where the range holds it — the PEA's 0–150 V, the GMA's ±5 V, another stage's −30…120 V —
and otherwise the end nearer 0 V (20 V of a 20–120 V stage): the voltage the stage rests at, its ``v_safe``
(:func:`hyst_common.profiles.custom_limits`), so the player starts where the stage is and leaves it there.
Every sample is inside ``[v_min, v_max]`` and within ``slew_max·dt`` of the previous one (the
final rate limiter guarantees it whatever the shapes ask for). Same arguments and seed → same samples.

:func:`from_samples` checks an excitation read from a file (``hyst excite --out`` writes one) against the same
limits, so the node plays a file only when it could have generated it.

Steps are ramped, not jumped: the discrete MBW model is a per-sample recursion, and a full-range jump within one
or two samples (what a 10⁵ V/s amplifier passes at 2 kHz) drives it far outside its valid range (measured: the
simulated stage undershot to its lower stop in 4 of 9 seeds and those bags fitted at 19–300 nm instead of 2 nm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hyst_common.profiles import rest_voltage

from .errors import ConfigError

__all__ = ["PARTS", "DEFAULT_PARTS", "BAND_PARTS", "PERIODIC_PARTS", "DEFAULT_RATE", "MIN_RATE", "MAX_RATE",
           "MAX_SECONDS", "ExcitationSpec", "Excitation", "build_excitation", "from_samples"]

#: Every part :func:`build_excitation` can play.
PARTS = ("steps", "sines", "triangles", "multisine", "sweep", "noise")
#: The parts that use the band ``f_lo`` … ``f_hi`` and ``seconds``, and those that use ``frequency``/``periods``.
BAND_PARTS = ("multisine", "sweep", "noise")
PERIODIC_PARTS = ("sines", "triangles")
#: The parts played when none are named (the excitation earlier sessions measured the lab workflow with).
DEFAULT_PARTS = ("steps", "sines", "triangles", "multisine", "sweep")
#: Sample rate (Hz) of ``hyst excite`` and ``hyst_excite_node`` when none is given, and the range both take.
DEFAULT_RATE = 1000.0
MIN_RATE, MAX_RATE = 1.0, 5000.0
#: Longest excitation built (s): an hour of identification. A longer one was an allocation of tens of GiB (a
#: traceback, or the process killed by the kernel) from one mistyped option (``--hold 1e6``).
MAX_SECONDS = 3600.0


@dataclass(frozen=True)
class ExcitationSpec:
    """What to play (SI: V, V/s, s, Hz).

    Attributes
    ----------
    v_min, v_max : float
        Allowed command range (V), inside the stage profile.
    slew_max : float
        Largest |du/dt| (V/s); ``inf`` = no limit.
    dt : float
        Sample period (s).
    parts : tuple of str
        Subset of :data:`PARTS`, played in this order.
    amplitudes : tuple of float
        Fractions of the range (0, 1] used by ``sines``/``triangles`` (one segment each) and, largest, by
        ``multisine``/``sweep``.
    frequency : float
        Frequency of the sines and triangles (Hz).
    periods : int
        Whole periods per sine/triangle amplitude.
    n_steps : int
        Number of random step levels.
    hold : float
        Hold of each step level and between parts (s).
    step_rise : float
        Raised-cosine rise/fall time of each step (s); 0 = jump (limited by ``slew_max`` only).
    f_lo, f_hi : float
        Band of the multisine and the sweep (Hz); ``f_hi`` must stay below the Nyquist frequency.
    seconds : float
        Length of the multisine, of the sweep and of the noise (s).
    seed : int
        Seed of step levels and multisine phases.
    """

    v_min: float = 0.0
    v_max: float = 150.0
    slew_max: float = math.inf
    dt: float = 5e-4
    parts: tuple = DEFAULT_PARTS
    amplitudes: tuple = (0.3, 0.6, 0.95)
    frequency: float = 2.0
    periods: int = 2
    n_steps: int = 8
    hold: float = 0.25
    step_rise: float = 0.005
    f_lo: float = 0.5
    f_hi: float = 50.0
    seconds: float = 4.0
    seed: int = 0

    def __post_init__(self) -> None:
        fin = (self.v_min, self.v_max, self.dt, self.frequency, self.hold, self.f_lo, self.f_hi, self.seconds)
        if not all(math.isfinite(v) for v in fin):
            raise ConfigError("excitation settings must be finite")
        if not self.v_min < self.v_max:
            raise ConfigError(f"v_min ({self.v_min} V) must be below v_max ({self.v_max} V)")
        if not self.dt > 0:
            raise ConfigError(f"dt must be positive, got {self.dt}")
        if not self.slew_max > 0:
            raise ConfigError(f"slew_max must be positive, got {self.slew_max}")
        bad = [p for p in self.parts if p not in PARTS]
        if bad or not self.parts:
            raise ConfigError(f"unknown excitation part(s) {bad or '(none)'}; choose from {', '.join(PARTS)}")
        if not self.amplitudes or not all(0.0 < a <= 1.0 for a in self.amplitudes):
            raise ConfigError(f"amplitudes must be fractions of the range in (0, 1], got {self.amplitudes}")
        nyq = 0.5 / self.dt
        # only what the parts use: the band's defaults refused a steps-only excitation at 10 Hz
        if set(self.parts) & set(BAND_PARTS) and not 0.0 < self.f_lo < self.f_hi < nyq:
            raise ConfigError(f"need 0 < f_lo < f_hi < Nyquist ({nyq:g} Hz), got {self.f_lo:g}, {self.f_hi:g}")
        if set(self.parts) & set(PERIODIC_PARTS) and not 0.0 < self.frequency < nyq:
            raise ConfigError(f"frequency must be in (0, {nyq:g}) Hz, got {self.frequency:g}")
        if self.periods < 1 or self.n_steps < 1 or self.hold < 0 or self.seconds <= 0 or not self.step_rise >= 0:
            raise ConfigError("periods and n_steps must be >= 1, hold >= 0 s, step_rise >= 0 s, seconds > 0 s")
        n = self.samples
        if n * self.dt > MAX_SECONDS:
            raise ConfigError(f"the excitation would last {n * self.dt:.4g} s ({n:.4g} samples); at most "
                              f"{MAX_SECONDS:g} s is built (check hold, periods, n_steps, step_rise, frequency, "
                              "seconds)")

    @property
    def samples(self) -> int:
        """How many samples :func:`build_excitation` makes of this spec, counted before building (float-safe
        for absurd settings: the check above refuses them before any array exists)."""
        def n(sec: float) -> float:
            return float(round(sec / self.dt))
        hold = max(1.0, n(self.hold))
        total = hold
        for part in self.parts:
            if part == "steps":
                total += (self.n_steps + 1) * (n(self.step_rise) + hold)
            elif part in PERIODIC_PARTS:
                total += len(self.amplitudes) * (round(self.periods / (self.frequency * self.dt)) + 1)
            else:
                total += n(self.seconds) + 1
            total += hold
        return int(min(total, 1e18))

    @property
    def rest(self) -> float:
        """Voltage every part starts and ends at: 0 V where ``[v_min, v_max]`` holds it, else the end nearer 0 V.

        For the two profiles the same as before (PEA 0 V = ``v_min``, GMA 0 V = the centre); a range centred
        elsewhere rested at its centre, 45 V on −30…120 V, while the stage rested at 0 V: a 45 V jump at the start.
        """
        return rest_voltage(self.v_min, self.v_max)


@dataclass(frozen=True)
class Excitation:
    """A generated excitation: ``u[k]`` (V) at ``t[k] = k·dt``; ``segments`` = ((name, first, stop), ...)."""

    t: np.ndarray
    u: np.ndarray
    segments: tuple = field(default_factory=tuple)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0


def _band(spec: ExcitationSpec, a: float) -> tuple[float, float]:
    """Lowest and highest voltage at amplitude fraction ``a``, anchored at the rest voltage."""
    r = spec.rest
    return r - a * (r - spec.v_min), r + a * (spec.v_max - r)


def _periodic(spec: ExcitationSpec, a: float, triangle: bool) -> np.ndarray:
    lo, hi = _band(spec, a)
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    phi0 = math.asin(max(-1.0, min(1.0, (spec.rest - c) / h)))  # start (and end) at rest
    n = int(round(spec.periods / (spec.frequency * spec.dt)))
    phase = phi0 + 2.0 * math.pi * spec.frequency * spec.dt * np.arange(n + 1)
    s = np.sin(phase)
    if triangle:
        s = (2.0 / math.pi) * np.arcsin(s)
    return c + h * s


def _fade(n: int, dt: float) -> np.ndarray:
    """Raised-cosine fade in and out over 10 % of the part (at most 0.5 s) each."""
    m = max(1, min(int(0.1 * n), int(0.5 / dt)))
    w = np.ones(n)
    ramp = 0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, m))
    w[:m], w[n - m:] = ramp, ramp[::-1]
    return w


def _banded(spec: ExcitationSpec, x: np.ndarray) -> np.ndarray:
    """Map a signal in [-1, 1] into the largest band and fade it from and back to rest."""
    lo, hi = _band(spec, max(spec.amplitudes))
    v = 0.5 * (lo + hi) + 0.5 * (hi - lo) * x
    return spec.rest + _fade(len(x), spec.dt) * (v - spec.rest)


def _multisine(spec: ExcitationSpec, rng: np.random.Generator) -> np.ndarray:
    t = spec.dt * np.arange(int(round(spec.seconds / spec.dt)) + 1)
    freqs = np.geomspace(spec.f_lo, spec.f_hi, 12)
    x = np.sin(2.0 * math.pi * freqs[:, None] * t[None, :] + rng.uniform(0, 2 * math.pi, (len(freqs), 1)))
    x = x.sum(axis=0) / (freqs.size ** 0.5)  # unit power per tone; peaks normalised below
    return _banded(spec, x / np.max(np.abs(x)))


def _sweep(spec: ExcitationSpec) -> np.ndarray:
    t = spec.dt * np.arange(int(round(spec.seconds / spec.dt)) + 1)
    k = (spec.f_hi - spec.f_lo) / spec.seconds
    return _banded(spec, np.sin(2.0 * math.pi * (spec.f_lo * t + 0.5 * k * t * t)))


def _noise(spec: ExcitationSpec, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise with every FFT bin outside [f_lo, f_hi] zeroed, peak-normalised into the band."""
    n = int(round(spec.seconds / spec.dt)) + 1
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, spec.dt)
    spectrum[(f < spec.f_lo) | (f > spec.f_hi)] = 0.0
    x = np.fft.irfft(spectrum, n)
    peak = float(np.max(np.abs(x)))
    if not peak > 0.0:  # a band holding no FFT bin of so short a part
        raise ConfigError(f"noise: no frequency of a {spec.seconds:g} s part lies in {spec.f_lo:g}..{spec.f_hi:g} Hz")
    return _banded(spec, x / peak)


def _steps(spec: ExcitationSpec, rng: np.random.Generator) -> np.ndarray:
    levels = np.r_[rng.uniform(spec.v_min, spec.v_max, spec.n_steps), spec.rest]
    n = max(1, int(round(spec.hold / spec.dt)))
    m = int(round(spec.step_rise / spec.dt))
    shape = 0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, m + 2)[1:-1])  # m samples strictly between levels
    out, prev = [], spec.rest
    for v in levels:
        out += [prev + (v - prev) * shape, np.full(n, v)]
        prev = v
    return np.concatenate(out)


def _rate_limit(u: np.ndarray, spec: ExcitationSpec) -> np.ndarray:
    """Clip to the range and the slew step sample by sample (the amplifier would do it anyway; we say it)."""
    u = np.clip(u, spec.v_min, spec.v_max)
    step = spec.slew_max * spec.dt
    if not math.isfinite(step) or np.all(np.abs(np.diff(u)) <= step):
        return u
    out = np.empty_like(u)
    prev = spec.rest
    for k, v in enumerate(u):  # short loop: only when a part is too steep for the slew limit
        prev = min(max(v, prev - step), prev + step)
        out[k] = prev
    return out


def build_excitation(spec: ExcitationSpec) -> Excitation:
    """Generate the excitation ``spec`` describes.

    Parameters
    ----------
    spec : ExcitationSpec

    Returns
    -------
    Excitation
        Starts with a hold at rest and ends at rest; every sample within the range and the slew limit.
    """
    rng = np.random.default_rng(spec.seed)
    hold = np.full(max(1, int(round(spec.hold / spec.dt))), spec.rest)
    pieces, segments, k = [hold], [], len(hold)
    for part in spec.parts:
        if part == "steps":
            chunk = [_steps(spec, rng)]
        elif part in ("sines", "triangles"):
            chunk = [_periodic(spec, a, part == "triangles") for a in spec.amplitudes]
        elif part == "multisine":
            chunk = [_multisine(spec, rng)]
        elif part == "noise":
            chunk = [_noise(spec, rng)]
        else:
            chunk = [_sweep(spec)]
        seg = np.concatenate(chunk)
        segments.append((part, k, k + len(seg)))
        pieces += [seg, hold]
        k += len(seg) + len(hold)
    u = _rate_limit(np.concatenate(pieces), spec)
    return Excitation(t=spec.dt * np.arange(len(u)), u=u, segments=tuple(segments))


def from_samples(t: np.ndarray, u: np.ndarray, spec: ExcitationSpec) -> Excitation:
    """An excitation given as samples (a file), checked against ``spec``'s limits; nothing is clipped.

    Parameters
    ----------
    t, u : ndarray
        Time (s) and command (V), as read from a ``t,u`` CSV (``hyst excite --out`` writes one).
    spec : ExcitationSpec
        Its ``dt``, ``v_min``, ``v_max``, ``slew_max`` and rest voltage are the limits; its parts are unused.

    Returns
    -------
    Excitation
        ``t`` re-based to start at 0 (k·dt), ``u`` as given, one segment named ``file``.

    Raises
    ------
    ConfigError
        Fewer than two samples, a sample period other than ``spec.dt`` (1 % tolerance) or an irregular one, a
        value outside the range, a step beyond the slew limit, or a start or end more than 0.1 % of the range away
        from the rest voltage (the player starts from rest and returns to it: a jump there is not ramped).
    """
    t = np.asarray(t, dtype=np.float64).ravel()
    u = np.asarray(u, dtype=np.float64).ravel()
    if t.size != u.size or t.size < 2:
        raise ConfigError(f"an excitation needs at least two samples of t and u, got {t.size} and {u.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u))):
        raise ConfigError("the excitation holds NaN or infinite values")
    steps = np.diff(t)
    if np.any(np.abs(steps - spec.dt) > 0.01 * spec.dt):
        k = int(np.flatnonzero(np.abs(steps - spec.dt) > 0.01 * spec.dt)[0])
        raise ConfigError(f"the excitation must be sampled every {spec.dt:g} s ({1 / spec.dt:g} Hz, the stage "
                          f"rate); between rows {k} and {k + 1} the step is {steps[k]:g} s")
    tol = 1e-9 * (spec.v_max - spec.v_min)
    out = np.flatnonzero((u < spec.v_min - tol) | (u > spec.v_max + tol))
    if out.size:
        k = int(out[0])
        raise ConfigError(f"{out.size} sample(s) outside {spec.v_min:g}..{spec.v_max:g} V, the first at "
                          f"t = {t[k] - t[0]:.6g} s: {u[k]:.6g} V")
    step = spec.slew_max * spec.dt * (1.0 + 1e-9)
    fast = np.flatnonzero(np.abs(np.diff(u)) > step)
    if fast.size:
        k = int(fast[0])
        raise ConfigError(f"{fast.size} step(s) faster than the slew limit {spec.slew_max:g} V/s, the first at "
                          f"t = {t[k + 1] - t[0]:.6g} s: {u[k]:.6g} -> {u[k + 1]:.6g} V")
    for where, v in (("starts", u[0]), ("ends", u[-1])):
        if abs(v - spec.rest) > 1e-3 * (spec.v_max - spec.v_min):  # a jump from rest the slew limit may pass
            # (1e5 V/s is 100 V a sample at 1 kHz) drives the per-sample MBW stage far off (module docstring)
            raise ConfigError(f"the excitation {where} at {v:.6g} V but the stage rests at {spec.rest:g} V: start "
                              "and end it at rest (hyst excite writes files that do)")
    return Excitation(t=spec.dt * np.arange(u.size), u=u.copy(), segments=(("file", 0, u.size),))
