"""The input range a model was identified on, and a note when it is run beyond it.

A fitted hysteresis model is an interpolation over the input levels and rates its record visited; beyond them it
extrapolates, and an MBW fit outside Remark 4.1 can diverge there (a generated GMA fit on ±0.8 V ran off to
infinity on a fresh ±3.8 V record). ``hyst fit --out`` and ``hyst diagnose --out`` store the range in the params
file's provenance (``fit.u_min``, ``fit.u_max``, V); ``hyst simulate`` and ``hyst compare`` say so when an input
leaves it.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["identified_range", "range_note", "TOLERANCE"]

#: Share of the identified span an input may pass either end by before the note: the excitation of a new record
#: rarely repeats the identification's extremes exactly, and a few % beyond them is still the same operating range.
TOLERANCE = 0.05


def identified_range(u) -> dict[str, float]:
    """``{"u_min": ..., "u_max": ...}`` (V) of the input a model is identified on, for the params file."""
    u = np.asarray(u, dtype=np.float64)
    u = u[np.isfinite(u)]
    return {"u_min": float(np.min(u)), "u_max": float(np.max(u))} if u.size else {}


def range_note(fit: Mapping, u, tolerance: float = TOLERANCE) -> str | None:
    """A sentence when ``u`` leaves the range in a params file's provenance ``fit`` by more than ``tolerance`` of
    its span, else None (also when the file does not record a range)."""
    lo, hi = fit.get("u_min"), fit.get("u_max")
    if not isinstance(lo, (int, float)) or not isinstance(hi, (int, float)) or not hi >= lo:
        return None
    u = np.asarray(u, dtype=np.float64)
    u = u[np.isfinite(u)]
    if not u.size:
        return None
    slack = tolerance * max(float(hi) - float(lo), 1e-12)
    beyond = (u < lo - slack) | (u > hi + slack)
    if not beyond.any():
        return None
    share = float(np.mean(beyond))
    return (f"the input reaches {np.min(u):.4g} .. {np.max(u):.4g} V, outside the {lo:.4g} .. {hi:.4g} V the model "
            f"was identified on ({share:.0%} of the samples): it extrapolates there and may be far off or diverge; "
            "identify it on a record that covers this range")
