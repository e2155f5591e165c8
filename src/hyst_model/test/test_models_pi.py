"""Prandtl-Ishlinskii (2.13): play operator known answers, analytic inverse, and the Model-protocol wrapper."""
import numpy as np
import pytest

from hyst_model.models import BASE_MODELS, PIModel, pi_inverse, pi_simulate, play_operators


def test_play_operator_known_answer():
    u = np.array([0.0, 1.0, 2.0, 1.5, 0.0, -1.0, 0.5])
    z = play_operators(u, np.array([0.5]), np.zeros(1))[:, 0]
    np.testing.assert_allclose(z, [0.0, 0.5, 1.5, 1.5, 0.5, -0.5, 0.0])


def test_inverse_pi_undoes_pi():
    rng = np.random.default_rng(0)
    r = np.linspace(0.5, 5, 10)
    p = rng.uniform(0.05, 0.3, 10)
    u = 8 * np.sin(np.linspace(0, 6 * np.pi, 3000)) * np.linspace(1, 0.3, 3000)  # minor loops too
    y = pi_simulate(0.8, p, r, u)
    q0, q, rr = pi_inverse(0.8, p, r)
    np.testing.assert_allclose(pi_simulate(q0, q, rr, y), u, atol=1e-9)


def test_inverse_refuses_non_invertible_weights():
    with pytest.raises(ValueError):
        pi_inverse(0.5, np.array([-0.6]), np.array([1.0]))


def test_pi_model_protocol_and_inverse_in_si():
    m = BASE_MODELS["pi"]({"n_play": 5, "r_max": 60.0, "u_scale": 15.0, "y_scale": 2e-6})
    assert isinstance(m, PIModel) and len(m.names) == 7
    theta = m.pack({"p0": 0.5, "p1": 0.2, "p3": 0.1, "offset": -1e-6})
    t = np.arange(2000) * 5e-4
    u = 75 + 75 * np.sin(2 * np.pi * 2 * t)
    y = m.simulate(theta, t, u)
    np.testing.assert_allclose(m.inverse(theta, y), u, atol=1e-7)
