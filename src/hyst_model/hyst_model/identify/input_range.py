"""The input and output ranges a model was identified on, and a note when it is run beyond them.

A fitted hysteresis model is an interpolation over the input levels and rates its record visited; beyond them it
extrapolates, and an MBW fit outside Remark 4.1 can diverge there (a generated GMA fit on ±0.8 V ran off to
infinity on a fresh ±3.8 V record). ``hyst fit --out`` and ``hyst diagnose --out`` store the range in the params
file's provenance (``fit.u_min``, ``fit.u_max``, V, and the measured output's ``fit.y_min``, ``fit.y_max``, m);
``hyst simulate`` and ``hyst compare`` say so when an input leaves it, and when the model's output goes far beyond
what the record measured (:func:`output_note`): a finite prediction can still be one no stage makes (on fresh
records of accuracy seed 50, fitted models erred by 0.9 mm to 2.5e11 m RMS on stages of a few µm; 5000138: inputs 1.6×
the identified range).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["identified_range", "stored_range", "range_note", "output_note", "TOLERANCE", "OUTPUT_SPANS"]

#: Share of the identified span an input may pass either end by before the note: the excitation of a new record
#: rarely repeats the identification's extremes exactly, and a few % beyond them is still the same operating range.
TOLERANCE = 0.05

#: How many identified output spans beyond either end of the measured output a prediction may reach before the
#: note: a stage driven over a wider input range moves further, but by a span more on either side (three times the
#: travel the record showed) it is no longer the stage the record measured.
OUTPUT_SPANS = 1.0


def identified_range(u, y=None) -> dict[str, float]:
    """``{"u_min", "u_max"}`` (V) of the input a model is identified on and, with ``y``, ``{"y_min", "y_max"}`` (m)
    of the measured output, for the params file."""
    out: dict[str, float] = {}
    for key, v in (("u", u), ("y", y)):
        if v is None:
            continue
        v = np.asarray(v, dtype=np.float64)
        v = v[np.isfinite(v)]
        if v.size:
            out.update({f"{key}_min": float(np.min(v)), f"{key}_max": float(np.max(v))})
    return out


def _stored(fit: Mapping, key: str) -> tuple[float, float] | None:
    """``(min, max)`` of ``key`` (``u``/``y``) in a params file's provenance, or None (an older file, a bad entry)."""
    lo, hi = fit.get(f"{key}_min"), fit.get(f"{key}_max")
    if not isinstance(lo, (int, float)) or not isinstance(hi, (int, float)) or not hi >= lo:
        return None
    return float(lo), float(hi)


def _share(x: float) -> str:
    """A share as a percentage that never reads 0 % for a share above zero."""
    return f"{x:.0%}" if x >= 0.01 else f"{x:.2%}" if x >= 1e-4 else "under 0.01%"


def stored_range(fit: Mapping, key: str = "u") -> tuple[float, float] | None:
    """``(min, max)`` of the input (``key="u"``, V) or measured output (``"y"``, m) a params file's provenance
    ``fit`` records, or None where it records none (an older file, a bad entry)."""
    return _stored(fit, key)


def _beyond(v, lo: float, hi: float, slack: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The finite samples of ``v`` and the mask of those more than ``slack`` outside ``[lo, hi]``; None if none is."""
    v = np.asarray(v, dtype=np.float64)
    v = v[np.isfinite(v)]
    beyond = (v < lo - slack) | (v > hi + slack)
    return (v, beyond) if beyond.any() else None


def range_note(fit: Mapping, u, tolerance: float = TOLERANCE) -> str | None:
    """A sentence when ``u`` leaves the range in a params file's provenance ``fit`` by more than ``tolerance`` of
    its span, else None (also when the file does not record a range)."""
    rng = _stored(fit, "u")
    if rng is None:
        return None
    lo, hi = rng
    found = _beyond(u, lo, hi, tolerance * max(hi - lo, 1e-12))
    if found is None:
        return None
    u, beyond = found
    share = float(np.mean(beyond))
    return (f"the input reaches {np.min(u):.4g} .. {np.max(u):.4g} V, outside the {lo:.4g} .. {hi:.4g} V the model "
            f"was identified on ({_share(share)} of the samples): it extrapolates there and may be far off or diverge; "
            "identify it on a record that covers this range")


def output_note(fit: Mapping, y, spans: float = OUTPUT_SPANS) -> str | None:
    """A sentence when the model output ``y`` (m) goes more than ``spans`` × the measured output's span beyond
    either end of the range in ``fit`` (``y_min``, ``y_max``), else None (also for a file without the range)."""
    rng = _stored(fit, "y")
    if rng is None or not rng[1] > rng[0]:
        return None
    lo, hi = rng
    found = _beyond(y, lo, hi, spans * (hi - lo))
    if found is None:
        return None
    y, beyond = found
    return (f"the model's output reaches {np.min(y) * 1e6:.4g} .. {np.max(y) * 1e6:.4g} µm, far beyond the "
            f"{lo * 1e6:.4g} .. {hi * 1e6:.4g} µm of the record it was identified on ({np.mean(beyond):.0%} of the "
            "samples more than its span outside): no stage of that record moves so far, the model extrapolates or "
            "diverges there")
