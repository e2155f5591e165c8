"""The saturation map of hyst_model (the model) and of hyst_sim (the truth) are one function, and a function:
monotonic and continuous for every strength, two-sided knees included (they meet at mid-range, never overlap)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hyst_model.effects.saturation import SaturationInverse, knee_width, soft_limit
from hyst_sim.truth_effects import saturation_kernel

# (top, bottom, width, two_sided): inside the knees, knees just touching, overlapping (strength 0.19 of a GMA
# stroke with knees 2x the loss: generated stages 1119 and 1204), one-sided with a knee below the whole range
CASES = [(10e-6, -10e-6, 2e-6, True), (10e-6, -10e-6, 10e-6, True), (10.67e-6, -10.67e-6, 13.58e-6, True),
         (5e-6, -20e-6, 40e-6, True), (20e-6, 0.0, 30e-6, False), (20e-6, -1.0, 5e-6, False)]


@pytest.mark.parametrize("top,bottom,w,two", CASES)
def test_model_and_sim_saturation_are_the_same_map(top, bottom, w, two):
    x = np.linspace(-40e-6, 40e-6, 4001)
    sim = np.array([saturation_kernel(float(v), bottom if two else -math.inf, top, w) for v in x])
    np.testing.assert_allclose(soft_limit(x, top, bottom, w, two), sim, rtol=0, atol=1e-18)


@pytest.mark.parametrize("top,bottom,w,two", CASES)
def test_saturation_is_monotonic_continuous_and_within_its_limits(top, bottom, w, two):
    x = np.linspace(-60e-6, 60e-6, 120001)
    y = soft_limit(x, top, bottom, w, two)
    d = np.diff(y)
    assert np.all(d >= 0) and np.sum(d > 0) > 0.5 * d.size  # tanh reaches its asymptote in floating point
    # continuous: no step larger than the grid step (slope ≤ 1 everywhere)
    assert np.max(d) <= (x[1] - x[0]) * (1 + 1e-9)
    assert np.all(y <= top) and (not two or np.all(y >= bottom))


def test_overlapping_knees_meet_at_mid_range_with_slope_one():
    top, bottom, w = 10.67e-6, -10.67e-6, 13.58e-6
    we = knee_width(top, bottom, w, True)
    assert we == pytest.approx(0.5 * (top - bottom))
    mid, h = 0.5 * (top + bottom), 1e-12
    slope = (soft_limit(np.array([mid + h]), top, bottom, w, True) - soft_limit(np.array([mid - h]), top, bottom,
                                                                               w, True)) / (2 * h)
    assert slope[0] == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("top,bottom,w,two", CASES)
def test_inverse_undoes_the_map_within_its_reach(top, bottom, w, two):
    inv = SaturationInverse(top, bottom, w, two)
    lo, hi = inv.bounds()
    x = np.linspace(-30e-6, 30e-6, 601)
    y = soft_limit(x, top, bottom, w, two)
    inside = (y > lo) & (y < hi)
    assert inside.sum() > 100
    back = np.array([inv.measure(float(v), 0.0) for v in y[inside]])
    np.testing.assert_allclose(back, x[inside], rtol=0, atol=1e-12)
