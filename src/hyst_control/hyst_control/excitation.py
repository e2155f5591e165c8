"""Open-loop voltage excitations for identification (issue 11, Build 3): numerical core, numpy only.

One excitation is a concatenation of parts, each starting and ending at the rest voltage, separated by holds:

``steps``      random levels (seeded) reached by a raised-cosine ramp of ``step_rise`` s and held ``hold`` s each
               — creep/settling, static loop points
``sines``      whole periods of a sine at several amplitudes (fractions of the range) — major and minor loops
``triangles``  the same with triangles (constant rate: rate-independence check)
``multisine``  log-spaced frequencies, random phases (seeded), faded in and out — dynamics and memory
``sweep``      a linear chirp ``f_lo`` → ``f_hi``, faded in and out — rate dependence, resonance

The rest voltage is ``v_min`` for a unipolar amplifier (PEA, 0–150 V) and the centre of the range for a bipolar
one (GMA, ±5 V). Every sample is inside ``[v_min, v_max]`` and within ``slew_max·dt`` of the previous one (the
final rate limiter guarantees it whatever the shapes ask for). Same arguments and seed → same samples.

Steps are ramped, not jumped: the discrete MBW model is a per-sample recursion, and a full-range jump within one
or two samples (what a 10⁵ V/s amplifier passes at 2 kHz) drives it far outside its valid range (measured: the
simulated stage undershot to its lower stop in 4 of 9 seeds and those bags fitted at 19–300 nm instead of 2 nm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError

__all__ = ["PARTS", "ExcitationSpec", "Excitation", "build_excitation"]

PARTS = ("steps", "sines", "triangles", "multisine", "sweep")


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
        Length of the multisine and of the sweep (s).
    seed : int
        Seed of step levels and multisine phases.
    """

    v_min: float = 0.0
    v_max: float = 150.0
    slew_max: float = math.inf
    dt: float = 5e-4
    parts: tuple = PARTS
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
        if not 0.0 < self.f_lo < self.f_hi < nyq:
            raise ConfigError(f"need 0 < f_lo < f_hi < Nyquist ({nyq:g} Hz), got {self.f_lo:g}, {self.f_hi:g}")
        if not 0.0 < self.frequency < nyq:
            raise ConfigError(f"frequency must be in (0, {nyq:g}) Hz, got {self.frequency:g}")
        if self.periods < 1 or self.n_steps < 1 or self.hold < 0 or self.seconds <= 0 or not self.step_rise >= 0:
            raise ConfigError("periods and n_steps must be >= 1, hold >= 0 s, step_rise >= 0 s, seconds > 0 s")

    @property
    def rest(self) -> float:
        """Voltage every part starts and ends at: ``v_min`` (unipolar) or the centre of the range (bipolar)."""
        return 0.5 * (self.v_min + self.v_max) if self.v_min < 0.0 < self.v_max else self.v_min


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
        else:
            chunk = [_sweep(spec)]
        seg = np.concatenate(chunk)
        segments.append((part, k, k + len(seg)))
        pieces += [seg, hold]
        k += len(seg) + len(hold)
    u = _rate_limit(np.concatenate(pieces), spec)
    return Excitation(t=spec.dt * np.arange(len(u)), u=u, segments=tuple(segments))
