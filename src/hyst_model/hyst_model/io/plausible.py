"""Plausibility of a record for a smart-material stage: catch unit mistakes before a "successful" nonsense fit.

A displacement in µm read as metres fits without complaint (a 4 041 482 nm RMSE); times in ms read as seconds
give a 2 Hz record. Nothing here refuses data — the rig may be unusual — but each implausible figure is named
with the likely cause and the option that fixes it, on stderr, before the fit.

The stroke limit is the rig's two stages' (:mod:`hyst_common.profiles`, which the driver, the sim and the
controller share): PEA 30 µm, GMA ±20 µm. An input beyond both amplifiers (PEA 0…150 V, GMA ±5 V) is not by itself
a mistake — another stage may be driven from ±10 V or 200 V — so only an input beyond :data:`INPUT_MAX` is named
(millivolts read as volts: a PEA's 150 V reads 150 000, a GMA's ±5 V ±5 000).
"""
from __future__ import annotations

import numpy as np

from hyst_common.profiles import PROFILES, V_SPAN

__all__ = ["plausibility", "STROKE_MAX", "V_RANGE", "INPUT_MAX", "RATE_RANGE", "STROKE_FACTOR"]

#: Largest stroke of the rig's stages (m): GMA ±20 µm.
STROKE_MAX = max(p.stroke for p in PROFILES.values())
#: Displacement spans beyond this many strokes are flagged (µm as m is 10⁶, mm as m 10³).
STROKE_FACTOR = 100.0
#: Widest amplifier range of the rig's stages (V): GMA −5 V … PEA 150 V.
V_RANGE = V_SPAN
#: Largest input magnitude (V) of a plausible smart-material amplifier input: high-voltage piezo amplifiers reach
#: about 1 kV; beyond it the column is taken for millivolts.
INPUT_MAX = 1000.0
#: Plausible sample rates (Hz) for a positioning record.
RATE_RANGE = (10.0, 100e3)


def plausibility(t: np.ndarray, u: np.ndarray, y: np.ndarray, input_unit: str = "V",
                 units_given: bool = False) -> list[str]:
    """Warnings (sentences) for figures no smart-material stage record has; empty when plausible.

    Parameters
    ----------
    t, u, y : ndarray
        The record in SI units (s, V, m), as read.
    input_unit : str
        The unit the input column was given in; the voltage range is only checked for volts.
    units_given : bool
        The user stated the units (``--units``): a displacement far beyond any stage's stroke is then not taken for
        a unit mistake (the Bouc-Wen benchmark's millimetres, given as m), only said to be no stage of this rig.
    """
    out: list[str] = []
    t, u, y = (np.asarray(a, dtype=np.float64) for a in (t, u, y))
    if t.size > 1:
        d = np.diff(t)
        d = d[d > 0]
        if d.size:
            fs = 1.0 / float(np.median(d))
            if not RATE_RANGE[0] <= fs <= RATE_RANGE[1]:
                out.append(f"the sample rate is {fs:.4g} Hz, outside {RATE_RANGE[0]:g} Hz – "
                           f"{RATE_RANGE[1] / 1e3:g} kHz: "
                           "are the times in ms or µs read as seconds? give the unit, e.g. --units ms,V,um")
    span = float(np.ptp(y)) if y.size else 0.0
    if span > STROKE_FACTOR * STROKE_MAX:
        said = (f"the displacement spans {span:.4g} m, {span / STROKE_MAX:.3g}× the largest stage stroke "
                f"({STROKE_MAX * 1e6:g} µm)")
        out.append(f"{said}, in the units given: no stage of this rig — the model is fitted, but the stage "
                   "profiles' limits do not describe it" if units_given else
                   f"{said}: is it in µm or nm read as metres? give the unit, e.g. --units s,V,um")
    if input_unit in ("V", "v") and u.size:
        lo, hi = float(np.min(u)), float(np.max(u))
        if max(abs(lo), abs(hi)) > INPUT_MAX:
            out.append(f"the input reaches {lo:.4g} … {hi:.4g} V, beyond any smart-material amplifier's "
                       f"{INPUT_MAX:g} V (the rig's: PEA 0 … 150 V, GMA ±5 V): is it in mV read as volts, or not "
                       "the amplifier's input? give the unit, e.g. --units s,mV,um")
    return out
