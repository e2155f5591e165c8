"""Diagnose never answers a bare "none" for a large error, and its refits never go backwards."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hyst_model.core import pea_default
from hyst_model.diagnose.diagnose import Fixed, default_fitter, diagnose
from hyst_model.diagnose.unexplained import loop_shape_share, operator_share
from hyst_model.effects.base import ComposedModel

DT = 1e-3
N = 12000


def _excitation(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Sines with a slowly varying amplitude (minor loops) plus a faster sine; seeded phases."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(N)
    ph = rng.uniform(0, 2 * np.pi, 3)
    u = (75 + 60 * np.sin(2 * np.pi * 1.0 * t + ph[0]) * (0.6 + 0.4 * np.sin(2 * np.pi * 0.07 * t + ph[1]))
         + 10 * np.sin(2 * np.pi * 5.3 * t + ph[2]))
    return t, np.clip(u, 0.0, 150.0)


def _play(u: np.ndarray, width: float) -> np.ndarray:
    """Backlash (play operator) in the input: an effect outside the library that changes the loop shape."""
    out, s = np.empty_like(u), u[0]
    for k, v in enumerate(u):
        s = min(max(s, v - width), v + width)
        out[k] = s
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_a_large_error_no_effect_explains_is_unexplained_never_none(seed):
    t, u = _excitation(seed)
    rng = np.random.default_rng(100 + seed)
    y = pea_default().simulate(_play(u, 12.0)) + 2e-9 * rng.standard_normal(N)
    d = diagnose(t, u, y)
    assert d.baseline_rmse > 50 * d.noise
    assert d.missing == "unexplained" and d.unexplained is not None
    # backlash is a loop-shape error: the level × direction table missed it ("outside the library" on 4 of 4
    # seeds), the hysteresis operator of the input predicts it
    assert d.unexplained.over_noise > 5 and d.unexplained.kind == "loop shape", d.unexplained
    assert d.unexplained.operator_share > 0.8 > d.unexplained.level_share
    obj = json.loads(json.dumps(d.to_json()))
    assert obj["missing"] == "unexplained" and 0.0 <= obj["unexplained"]["loop_shape_share"] <= 1.0
    assert "explains it significantly" in obj["explanation"]


@pytest.mark.parametrize("seed", [0, 1])
def test_clean_stage_is_still_none(seed):
    t, u = _excitation(seed)
    rng = np.random.default_rng(200 + seed)
    y = pea_default().simulate(u) + 2e-9 * rng.standard_normal(N)
    d = diagnose(t, u, y)
    assert d.missing == "none" and d.unexplained is None


def test_loop_shape_share_separates_level_functions_from_time_functions():
    t, u = _excitation(3)
    rng = np.random.default_rng(3)
    train = np.arange(N) < int(0.75 * N)
    level = 1e-7 * ((u - 75) / 75) ** 2 + 1e-7 * np.sign(np.gradient(u)) * 0.3
    assert loop_shape_share(u, level + 1e-9 * rng.standard_normal(N), train) > 0.8
    for f_hz in (0.013, 0.13, 0.41):                  # time-only errors: slow trends and beats with the input
        assert loop_shape_share(u, 1e-7 * np.sin(2 * np.pi * f_hz * t + 0.4), train) < 0.3, f_hz
    step = 1e-7 * (t > 8.0)                           # a load change late in the record
    assert loop_shape_share(u, step, train) < 0.3
    assert loop_shape_share(u, 1e-9 * rng.standard_normal(N), train) < 0.05


def _pi(u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A Prandtl–Ishlinskii stage (m): seeded weights on play operators whose radii are not PLAY_RADII's."""
    radii = np.sort(rng.uniform(0.0, 60.0, 6))
    w = rng.uniform(0.2, 1.0, 6)
    return 1e-7 * sum(wi * _play(u, r) for wi, r in zip(w, radii))


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_operator_share_sees_another_hysteresis_that_the_level_table_misses(seed):
    """What an MBW leaves of another hysteresis, e = H(u) − ŷ, depends on the input's history and on the model's
    own memory, not on level and direction alone: the level × direction table does not predict it out of sample
    (the Prandtl–Ishlinskii truths of the accuracy benchmark were labelled "outside the library" in 15 of 16),
    a Prandtl–Ishlinskii operator of the input with ŷ rescaled does. A load change in mid-record is not
    predicted by either: the second half's error is no function of the first half's."""
    t, u = _excitation(seed)
    rng = np.random.default_rng(seed)
    yhat = pea_default().simulate(u)
    vi = np.flatnonzero(np.arange(N) % 8 >= 6)      # held-out samples across the record, as diagnose's blocks
    first = np.arange(vi.size) < vi.size // 2
    noise = 2e-9 * rng.standard_normal(N)
    h = _pi(u, rng)
    e = h * (np.std(yhat) / np.std(h)) - yhat + noise  # the stage is H at the model's scale
    assert operator_share(u, e, yhat, vi, first) > 0.9
    assert loop_shape_share(u[vi], e[vi], first) < 0.5
    # the stage's gain drops by 20 % at a moment in mid-record; the model fitted to the whole record takes the
    # average gain, so it errs one way before and the other way after
    g = yhat - yhat.min()
    load = np.where(t > t[-1] * rng.uniform(0.4, 0.6), -0.2 * g, 0.0)
    load = load - (load @ g) / (g @ g) * g + noise
    assert operator_share(u, load, yhat, vi, first) < 0.3
    assert operator_share(u, noise, yhat, vi, first) < 0.05
    for f_hz in (0.013, 0.13):                       # slow trends are no function of the input's history either
        assert operator_share(u, 1e-7 * np.sin(2 * np.pi * f_hz * t + 0.4), yhat, vi, first) < 0.3, f_hz


def test_a_joint_refit_that_ends_worse_never_loses_the_candidate():
    """A fitter that spoils every joint refit (a local minimum, stopped early): the screened point stands."""
    t, u = _excitation(4)
    rng = np.random.default_rng(4)
    y = pea_default().simulate(u) + 20e-9 * t + 2e-9 * rng.standard_normal(N)   # 20 nm/s drift

    def spoiling_fitter(model, tt, uu, yy, theta0):
        th = default_fitter(model, tt, uu, yy, theta0)
        joint = isinstance(model, ComposedModel) and not isinstance(model.base, Fixed)
        if joint and theta0 is not None:
            th = th.copy()
            th[0] *= 1.3          # zeta1 off by 30 %: far worse than where the refit started
        return th

    d = diagnose(t, u, y, fitter=spoiling_fitter)
    # the screened point (drift on the base held fixed) is all that is left once the refit is spoiled; before
    # the guard the candidate kept the screen's RMSE but was never marked significant → "none"/"unexplained"
    assert d.missing == "drift", (d.missing, d.explanation)
    best = d.candidates[0]
    assert best.significant and best.improvement > 1.1 and best.t_stat > 3
