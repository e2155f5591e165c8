"""The fused normal equations: JᵀJ, Jᵀr, rᵀr summed sample by sample in order (bit for bit), so a faster kernel
cannot move a fit."""
import numpy as np

from hyst_model.identify.lm import _normal_equations
from hyst_model.model import MBWModel


def _sequential(J: np.ndarray, r: np.ndarray):
    """Each element summed over the samples in order, in plain Python (the reference order)."""
    n, p = J.shape
    H = np.zeros((p, p))
    g = np.zeros(p)
    rr = 0.0
    for k in range(n):
        rr += r[k] * r[k]
        for i in range(p):
            g[i] += J[k, i] * r[k]
            for j in range(i, p):
                H[i, j] += J[k, i] * J[k, j]
    return np.triu(H) + np.triu(H, 1).T, g, rr


def test_lm_normal_equations_sum_in_order_bit_for_bit():
    rng = np.random.default_rng(5)
    J = rng.normal(size=(300, 7)) * np.logspace(-3, 3, 7)
    r = rng.normal(size=300)
    H, g, rr = _normal_equations(J, r)
    Hs, gs, rrs = _sequential(J, r)
    np.testing.assert_array_equal(H, Hs)
    np.testing.assert_array_equal(g, gs)
    assert rr == rrs
    np.testing.assert_array_equal(H, H.T)


def test_mbw_fused_normal_equations_are_those_of_its_jacobian():
    """The MBW's fused pass gives what its stored Jacobian gives, summed in the same order: bit for bit."""
    rng = np.random.default_rng(8)
    n = 1500
    t = np.arange(n) * 5e-4
    u = 75.0 + 60.0 * np.sin(2 * np.pi * 3.0 * t) * np.exp(-t)
    model = MBWModel(u_scale=15.0, y_scale=3e-6)
    theta = model.theta0
    y = model.simulate(theta, t, u) + 2e-9 * rng.normal(size=n)
    scale = 1.7e-6
    H, g, rr = model.normal_equations(theta, t, u, 0, y, scale)
    yhat, J = model.simulate_jac(theta, t, u)
    r = (yhat - y) / scale
    Hs, gs, rrs = _sequential(np.ascontiguousarray(J / scale), r)
    np.testing.assert_allclose(H, Hs, rtol=1e-12, atol=0)
    np.testing.assert_allclose(g, gs, rtol=1e-12, atol=1e-300)
    assert np.isclose(rr, rrs, rtol=1e-12)
    np.testing.assert_array_equal(H, H.T)
