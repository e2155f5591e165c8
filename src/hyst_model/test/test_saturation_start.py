"""Saturation's data-driven start when the base model already imitates part of the limit."""
from __future__ import annotations

import numpy as np

from hyst_model.effects.saturation import soft_limit
from hyst_model.spec import build_model

CFG = {"dt": 5e-4, "u_scale": 15.0, "y_scale": 5.42e-6}
T = np.arange(4000) * 5e-4
U = 75.0 + 70.0 * np.sin(2 * np.pi * 2.0 * T)
X = 15e-6 + 12e-6 * np.sin(2 * np.pi * 2.0 * T)  # the base model's output: 3-27 um


def _start(residual: np.ndarray) -> dict:
    return build_model("mbw", ["saturation"], CFG).effects[0].start(T, U, X + residual, residual)


def test_a_limit_the_base_half_imitates_still_gets_a_knee_to_start_from():
    """Generated GMA stage 1119: the base bent its loop into the stroke limit (psi2 < 0, alpha2 > 0) and left only
    the sharp tip of the knee, with the bend's overshoot just below it; no knee of the grid had the residual's size
    (every share negative or > 2), the start fell back to the default limits far outside the stroke, where the fit
    has no gradient (saturation alone: 708 nm -> 708 nm; started at the knee the residual shows: 176 nm)."""
    tip = soft_limit(X, 27e-6 - 0.24e-6 + 0.2e-6, -1.0, 0.2e-6, False) - X      # a sharp knee at the very top
    bend = soft_limit(X, 27e-6 - 3.6e-6 + 2e-6, -1.0, 2e-6, False) - X          # the base's imitation of a broad one
    s = _start(tip - 0.02 * bend)
    assert s, "no start: the default limits would leave the fit without a gradient"
    assert 26e-6 < s["top"] < 29e-6 and s["width"] <= 2.4e-6, s  # at the tip, a sharp knee


def test_no_knee_in_the_residual_gives_no_knee_inside_the_stroke():
    noise = 2e-9 * np.random.default_rng(0).standard_normal(T.size)
    s = _start(noise)
    assert not s or s["top"] > X.max() - 0.5 * np.ptp(X), s  # none, or one the noise happened to favour
