"""EPSO (3.22)–(3.27): the pieces against the equations, seeding, bounds, and that the swarm actually optimises."""
import numpy as np
import pytest

from hyst_model.core import TABLE31_BOUNDS, MBWParams
from hyst_model.identify import fit
from hyst_model.identify.epso import I_MAX, I_MIN, PARTICLES, RHO1, RHO2, EPSOFit, chaotic_sequence, inertia
from hyst_model.models import BASE_MODELS

TRUE = MBWParams(0.45, 0.02, 0.03, 0.05, 0.02, -0.05, 0.99, 0.99, u_scale=15.0, y_scale=5e-6, offset=-1e-6)


def _record(n=1500):
    t = np.arange(n) * 5e-4
    u = 75 + 60 * np.sin(2 * np.pi * 3 * t) + 10 * np.sin(2 * np.pi * 17 * t)
    return t, u, TRUE.simulate(u)


def test_constants_are_the_thesis_values():
    assert (RHO1, RHO2, I_MAX, I_MIN, PARTICLES) == (1.5, 2.5, 0.9, 0.2, 40)


def test_chaotic_acceleration_is_the_logistic_map_3_22():
    s = chaotic_sequence(0.3, 4)
    np.testing.assert_allclose(s, [0.3, 0.84, 4 * 0.84 * 0.16, 4 * (4 * 0.84 * 0.16) * (1 - 4 * 0.84 * 0.16)])
    assert np.all((chaotic_sequence(0.123, 1000) > 0) & (chaotic_sequence(0.123, 1000) < 1))


def test_inertia_weight_3_25():
    assert inertia(0, 100, 0.5) == pytest.approx(0.9)
    assert inertia(100, 100, 0.0) == pytest.approx(0.2)
    assert inertia(50, 100, 0.7) == pytest.approx(0.9 - 0.7 * np.exp(-0.014) * 0.5)


def test_seeded_runs_repeat_and_improve_within_table31_bounds():
    t, u, y = _record()
    model = BASE_MODELS["mbw"]({"u_scale": 15.0, "y_scale": 5e-6, "offset_bound": 1e-5})
    a = EPSOFit(model, iterations=25, seed=7).fit(t, u, y)
    b = EPSOFit(model, iterations=25, seed=7).fit(t, u, y)
    c = EPSOFit(model, iterations=25, seed=8).fit(t, u, y)
    np.testing.assert_array_equal(a.theta_, b.theta_)
    assert not np.array_equal(a.theta_, c.theta_)
    h = a.result_.history
    assert all(h[i + 1] <= h[i] for i in range(len(h) - 1)) and h[-1] < 0.5 * h[0]
    assert a.result_.n_evaluations >= 26 * 40
    for name, (lo, hi) in TABLE31_BOUNDS.items():
        assert lo <= a.params_[name] <= hi


def test_epso_progress_reports(capsys):
    t, u, y = _record(500)
    lines = []
    fit(BASE_MODELS["bw"]({"u_scale": 15.0, "y_scale": 5e-6}), t, u, y, method="epso", seed=1, iterations=20,
        progress=lines.append)
    assert len(lines) >= 10 and "iteration 20/20" in lines[-1] and "best RMSE" in lines[-1]
