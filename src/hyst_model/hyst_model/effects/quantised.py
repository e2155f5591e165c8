"""The noise floor of a reading quantised in steps not fine against its noise (a digital sensor, a coarse ADC).

Second differences (:func:`.signals.noise_floor`) read white noise, and quantisation error is white only while the
noise before the quantiser dithers it: Widrow's condition, a white part σ of at least half the step q. Below it the
error is not white and the second differences misread it both ways: where the position hovers at a threshold the
reading flips by a step from sample to sample — an anti-correlated error the differences overstate (1.1–1.6× on
generated records with q = 2–10 σ) — and where it creeps or holds it is a staircase whose differences are mostly
exactly zero (the median absolute deviation then says 0 and the floor vanished, or its fallback read the steps of
a step record: 636 nm for a 2.9 nm error). Above it the error is white, but the second differences of a reading on
a lattice are whole steps, so the median they rest on moves in half steps: 0.7–1.3× the error for σ between 0.5 q
and 2 q (a sim stage's 2 nm noise on 2 nm steps: 0.94–1.17×). A model that is exact still leaves the quantisation
error, so the floor is its RMS with the noise, read here by local fits instead:

* :func:`lattice_step` finds the step: every change of the reading a whole multiple of the smallest one;
* :func:`local_noise` fits a quadratic to each run of :data:`WINDOW` samples and takes the median of the
  residual variances (corrected for the median's bias): the error's variance whatever its correlation over a
  sample or two, while the position's smooth course stays in the fit;
* :func:`quantised_floor` uses them where the reading is on a lattice and its error is below :data:`COARSE`
  steps, and never below q/√12, the RMS of the quantisation error alone (a staircase the local fits follow).
  Elsewhere it says so (step 0) and the second differences stand, bit for bit.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["lattice_step", "local_noise", "quantised_floor", "WINDOW"]

#: Samples per local fit: long against an error correlated over a sample or two, short against the position's course.
WINDOW = 12
#: Share of the changes that must be whole multiples of the step (a rare glitch may not be).
ON_LATTICE = 0.99
#: How far from a whole multiple a change may be, in steps (a reading printed to fewer digits than it had).
TOLERANCE = 0.02
#: The smallest change may be this many steps at most (a fast record whose reading never changes by one step).
MAX_DIVISOR = 8
#: Local fits read the floor of a reading on a lattice whose error is below this many steps. Second differences
#: of a reading on a lattice are whole steps too, so the median absolute deviation they rest on moves in half
#: steps — a floor that moves by 0.3 q: within 5 % only from an error of 3 q up (they misread 0.7–1.3× between
#: 0.5 and 2 q, on a sim stage's 2 nm noise and 2 nm steps 0.94–1.17×). Local fits read it within a few % at every
#: ratio.
COARSE = 3.0


def lattice_step(y: np.ndarray) -> float:
    """The step q (same unit as ``y``) of the lattice the reading lies on, or 0.0 where it does not.

    The step is the largest of the smallest change between samples and its parts (up to :data:`MAX_DIVISOR`) of
    which at least :data:`ON_LATTICE` of all changes are whole multiples to :data:`TOLERANCE` (the lattice's zero
    may sit anywhere: only changes are read). A reading of floats that are not quantised has changes of every size
    and is not on a lattice."""
    y = np.asarray(y, dtype=np.float64)
    if y.size < 3 or not np.all(np.isfinite(y)):
        return 0.0
    d = np.abs(np.diff(y))
    # a change below this is the same level read twice: (a + k q) − (a + k q) in floats need not be exactly 0
    nz = d[d > 1e-9 * max(float(np.ptp(y)), 1e-300)]
    if nz.size < 10:
        return 0.0
    smallest = float(np.min(nz))
    for k in range(1, MAX_DIVISOR + 1):   # a stage that never moves less than k steps a sample: its k-th part
        q = smallest / k
        r = nz / q
        whole = np.round(r)
        if float(np.mean(np.abs(r - whole) <= TOLERANCE)) >= ON_LATTICE:
            # a reading changes by different numbers of steps, or not at all; every change alike is a noiseless
            # record moving at a constant speed (a simulated ramp), not a quantiser
            return q if nz.size < d.size or np.unique(whole).size > 1 else 0.0
    return 0.0


def local_noise(x: np.ndarray, window: int = WINDOW) -> float:
    """Noise RMS of ``x`` (same unit) from quadratic fits over runs of ``window`` samples: the median of the runs'
    residual variances, each over ``window − 3`` degrees of freedom, divided by the median of χ²ᵥ/ν
    (Wilson–Hilferty: (1 − 2/(9ν))³), so white Gaussian noise reads its σ. The median leaves out the runs a step
    or a fast transient passes through. 0.0 for fewer than one run."""
    x = np.asarray(x, dtype=np.float64)
    n = x.size // window
    if n < 1:
        return 0.0
    runs = x[:n * window].reshape(n, window)
    k = np.arange(window, dtype=np.float64) - 0.5 * (window - 1)
    basis = np.vander(k, 3)
    proj = basis @ np.linalg.pinv(basis)
    res = runs - runs @ proj.T
    nu = window - 3
    var = np.einsum("ij,ij->i", res, res) / nu
    return float(math.sqrt(float(np.median(var)) / (1.0 - 2.0 / (9.0 * nu)) ** 3))


def quantised_floor(y: np.ndarray, e: np.ndarray | None = None, step: float | None = None) -> tuple[float, float]:
    """``(floor, q)`` of a reading ``y`` on a coarse lattice (m RMS, m), given a model's residual ``e`` on it;
    ``(0.0, 0.0)`` where the reading is not on a lattice, its step is fine enough for second differences, or it
    is shorter than one run of :data:`WINDOW` samples.

    The floor is the smaller local reading of ``y`` and ``e`` (each only overstates: the position's course in
    ``y``, the model's error in ``e``), at least q/√12. The step counts where that reading is below
    :data:`COARSE` steps. ``step``: the lattice's step when already known —
    ``y`` may then be off it (the reading with lines the input does not drive taken out, whose power is not the
    sensor's noise)."""
    q = lattice_step(y) if step is None else float(step)
    if q <= 0.0 or np.asarray(y).size < WINDOW:
        return 0.0, 0.0
    reads = [local_noise(y)]
    if e is not None:
        le = local_noise(e)
        if le > 0.0:
            reads.append(le)
    loc = min(reads)
    if loc >= COARSE * q:
        return 0.0, 0.0
    return max(loc, q / math.sqrt(12.0)), q
