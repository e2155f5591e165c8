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


def _composed_problem(mask: bool, a: int = 0):
    from hyst_model.effects import compose
    from hyst_model.identify.base import TrainProblem
    from hyst_model.identify.result import Split, block_mask

    rng = np.random.default_rng(11)
    n = 3000
    t = np.arange(n) * 5e-4
    u = 75.0 + 60.0 * np.sin(2 * np.pi * 3.0 * t)
    m = compose(MBWModel(u_scale=15.0, y_scale=3e-6), ["delay", "creep"], {"u_scale": 15.0, "y_scale": 3e-6})
    y = m.simulate(m.theta0, t, u) + 3e-9 * rng.normal(size=n)
    split = (Split(0, n, 0, n, "interleaved", val_mask=block_mask(n)) if mask
             else Split(a, 2400, 2400, n, "tail"))
    return m, TrainProblem(m, t, u, y, split)


def test_composed_normal_equations_are_those_of_residuals_jac_bit_for_bit():
    """The fused pass (mask, 1/scale and finiteness in the compiled sum) gives what ``residuals_jac`` and
    :func:`normal_from_jac` give, to the last bit: with a scored window starting later, with an interleaved
    hold-out, and a diverging point rejected the same way."""
    from hyst_model.identify.lm import normal_from_jac

    for mask, a in ((False, 0), (False, 300), (True, 0)):
        m, p = _composed_problem(mask, a)
        assert p.has_jac and not p.has_normal
        th = m.theta0 * 1.01
        H, g, rr = p.normal_equations(th)
        Hs, gs, rrs = normal_from_jac(p.residuals_jac)(th)
        np.testing.assert_array_equal(H, Hs)
        np.testing.assert_array_equal(g, gs)
        assert rr == rrs and np.isfinite(rr)
        if mask:  # the masked rows are not scored: a different mask gives different sums
            assert p.keep is not None and not p.keep.all()
    bad = m.theta0.copy()
    bad[0] = np.nan  # a point whose simulation is not finite
    H, g, rr = p.normal_equations(bad)
    assert rr == np.inf and not H.any() and not g.any()
    assert normal_from_jac(p.residuals_jac)(bad)[2] == np.inf


def test_a_trial_cost_is_the_sum_of_the_residuals_squares_bit_for_bit():
    """The fused trial cost (the squares summed in the simulation's pass) is what summing ``residuals`` gives,
    masked and unmasked, and a diverging point costs the penalty on every kept row, as there."""
    from hyst_model.identify.lm import sum_squares

    for mask, a in ((False, 0), (False, 300), (True, 0)):
        m, p = _composed_problem(mask, a)
        for th in (m.theta0 * 1.01, m.theta0 * 0.97):
            rr = p.sum_squares(th)
            assert rr == sum_squares(np.ascontiguousarray(p.residuals(th))) and np.isfinite(rr)
    bad = m.theta0.copy()
    bad[0] = np.nan
    n_kept = int(p.keep.sum())
    assert p.sum_squares(bad) == sum_squares(np.full(n_kept, p.PENALTY)) == sum_squares(p.residuals(bad))
    n = p.n_eval
    p.sum_squares(bad)  # the same point again: remembered, not simulated
    assert p.n_eval == n
