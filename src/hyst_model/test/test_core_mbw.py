"""Core MBW recursion: known answers computed by hand and the defaults' documented stroke."""
import numpy as np

from hyst_model.core import THESIS_FIG38, mbw_simulate, mbw_simulate_batch, mbw_step, pea_default


def test_step_matches_hand_computation():
    p = THESIS_FIG38.vector
    y_prev, u, u_prev = 0.3, 2.0, 1.5
    nu = u - p[7] * u_prev
    v = abs(u - u_prev)
    expected = (p[6] * y_prev + (p[0] + p[1] * v) * nu - (p[2] + p[3] * v) * abs(nu) * y_prev
                - (p[4] + p[5] * v) * nu * abs(y_prev))
    assert mbw_step(p, y_prev, u, u_prev) == expected


def test_simulate_equals_repeated_step_and_batch():
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(0, 0.1, 500))
    p = THESIS_FIG38.vector
    y = mbw_simulate(p, u, 0.0, np.nan)
    yp, up, ref = 0.0, u[0], []
    for uk in u:
        yp = mbw_step(p, yp, uk, up)
        up = uk
        ref.append(yp)
    np.testing.assert_allclose(y, ref, rtol=0, atol=0)
    Y = mbw_simulate_batch(np.vstack([p, p * 0.99]), u, np.zeros(2))
    np.testing.assert_array_equal(Y[0], y)
    assert not np.allclose(Y[1], y)


def test_pea_default_full_stroke_is_30_um():
    p = pea_default()
    y = p.simulate(np.full(2000, 150.0))
    assert abs(y[-1] - 30e-6) < 0.5e-6
    assert abs(p.simulate(np.zeros(10))[-1]) < 1e-12
