"""Sensor noise the white floor misses: the noise measured where the record holds its input still.

The floor of :func:`~hyst_model.effects.signals.noise_floor` reads second differences, which see white noise
only. A sensor whose electronics are slower than the sampling (a capacitive sensor's output filter, an
anti-aliasing stage set low) or a bench that vibrates adds noise that is band-limited — *coloured* — and that
floor misses most of it: a generated stage with no effect and low-passed sensor noise 1–3× the white part was
answered ``unexplained`` (6 of 24), its complete model 2.1–2.6× "the floor".

Where the record holds the input still (steps with holds, the identification schedule's steps), the stage is at
rest up to slow motion — creep, drift, the tail of a step's transient — and what the sensor adds is there to be
read. :func:`hold_noise` takes the second half of each hold of at least ``MIN_HOLD_S`` (a mode rung by the step
has decayed), removes a quadratic trend (creep and drift over it) and takes the ``QUANTILE`` of the holds' noise
variances: the noise is the same in every hold, while whatever else the stage does there differs from hold to
hold and only raises some of them. On 151 generated step and mix records with white noise and every kind of effect
(creep, modes, drift, saturation, delay, pairs, effects outside the library; three families, 1 and 2 kHz) it came
out at 0.39–1.01× the white floor; with low-passed noise (50 records) at 1.19–2.25×. A hold is read when it lasts
``MIN_HOLD_S`` and its second half has at least 64 samples: below about 500 Hz sampling, ``hyst excite``'s 0.25 s
holds are too short. The diagnosis takes it as the floor where it exceeds the white floor
by more than ``MARGIN`` (its spread on white noise); a record without holds keeps the white floor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["HeldNoise", "hold_noise", "not_white", "rest_noise", "still_spans", "MIN_HOLD_S", "MIN_HOLDS",
           "QUANTILE", "MARGIN", "HINT_BELOW"]

#: Holds shorter than this (s) are not read: their second half would be within a step's transient (``hyst excite``
#: holds its steps 0.25 s).
MIN_HOLD_S = 0.2
#: At least this many holds (a quantile of fewer says little).
MIN_HOLDS = 4
#: The quantile of the holds' noise variances taken (low: a hold where the stage still moves only raises its own).
QUANTILE = 0.25
#: The hold noise replaces the white floor only when larger than this × it: on white noise it stays below 1.01×.
MARGIN = 1.1
#: Below this × the white floor, an unexplained remainder of a record without holds may be noise that is not
#: white (band-limited noise 1–3× the white part leaves a complete model at 1.4–3.2× it; 2.0–2.6× on the six such
#: records of generated seed 66 answered ``unexplained``): the diagnosis says so and how to give the sensor's noise.
HINT_BELOW = 5.0
#: A white part below this share of the output's range is no sensor's (a noiseless simulated record: the Δ² of its
#: smooth motion; a 0.1 nm sensor on a 100 µm stroke is 1e-6).
_NOISELESS = 1e-7
#: Fewest samples read in one hold's second half.
_MIN_SAMPLES = 64
#: The input counts as held while it stays within this share of its range: a command held by a DAC or a
#: program is exactly constant; a slow input is not a hold (a 2–20 Hz noise input moves by less than 0.2 % of its
#: range per sample, and the output with it: read as noise, 135× the white floor).
_STILL = 1e-7


def still_spans(u: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    """Index ranges ``[a, b)`` of at least ``min_len`` samples over which ``u`` stays within :data:`_STILL` of its
    range (none for a constant input: a record without steps has no holds to compare)."""
    span = float(np.ptp(u)) if u.size else 0.0
    if not span > 0:
        return []
    tol = _STILL * span
    cuts = np.flatnonzero(np.abs(np.diff(u)) > tol) + 1
    edges = np.concatenate([[0], cuts, [u.size]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])
            if b - a >= min_len and np.ptp(u[a:b]) <= tol]


def not_white(reading: "HeldNoise | None", white: float, y: np.ndarray) -> bool:
    """Whether a holds' ``reading`` shows noise beyond the ``white`` part: by more than :data:`MARGIN`, on a record
    that has noise at all (a white part above 1e-7 of its range: a noiseless simulated record's holds read only
    what its stage does there)."""
    span = float(np.ptp(y)) if np.size(y) else 0.0
    return reading is not None and white > _NOISELESS * span and reading.rms > MARGIN * white


def rest_noise(u: np.ndarray, y: np.ndarray) -> float:
    """The sensor noise (RMS, m) of a record of the stage at rest: ``y`` with a quadratic trend removed (drift and
    the tail of creep over it). ``ValueError`` where the input ``u`` moves (more than 1e-6 of its level, at least
    1 µV) or the record is shorter than 64 samples."""
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if y.size < _MIN_SAMPLES:
        raise ValueError(f"a record at rest needs at least {_MIN_SAMPLES} samples, not {y.size}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise ValueError("the record at rest holds non-finite values")
    moved = float(np.ptp(u))
    if moved > 1e-6 * max(float(np.max(np.abs(u))), 1.0):
        raise ValueError(f"the input moves by {moved:.3g} V in the record at rest: hold it still to read the noise")
    return float(np.sqrt(_detrended_var(y)))


def _detrended_var(y: np.ndarray) -> float:
    """Variance of ``y`` about its least-squares quadratic trend (3 degrees of freedom taken)."""
    x = np.linspace(-1.0, 1.0, y.size)
    r = y - np.polyval(np.polyfit(x, y, 2), x)
    return float(r @ r) / (y.size - 3)


@dataclass(frozen=True)
class HeldNoise:
    """The sensor noise read in a record's holds (SI: m)."""

    rms: float      # m: the noise RMS, the QUANTILE of the holds'
    holds: int      # how many holds were read
    samples: int    # samples read over all of them


def hold_noise(t: np.ndarray, u: np.ndarray, y: np.ndarray) -> HeldNoise | None:
    """The output noise (RMS, m) where the input ``u`` is held still, or None where the record has fewer than
    :data:`MIN_HOLDS` holds of at least :data:`MIN_HOLD_S` (see the module docstring).

    Parameters
    ----------
    t, u, y : ndarray
        Time (s), input (V) and measured output (m), the same length.
    """
    t = np.asarray(t, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if t.size < 2 * _MIN_SAMPLES or not np.all(np.isfinite(y)):
        return None
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return None
    var, used = [], 0
    for a, b in still_spans(u, int(np.ceil(MIN_HOLD_S / dt))):
        seg = y[a + (b - a) // 2:b]
        if seg.size < _MIN_SAMPLES:
            continue
        var.append(_detrended_var(seg))
        used += seg.size
    if len(var) < MIN_HOLDS:
        return None
    return HeldNoise(float(np.sqrt(np.quantile(var, QUANTILE))), len(var), used)
