"""Parameters no sample of the record reaches are moved out of the way, the output on the record unchanged
(:mod:`hyst_model.effects.settle`): a two-sided saturation's lower stop fitted just below the record's lowest
output clipped every wider excursion (generated GMA stage 6400182: 1.57 µm on a fresh record, 2.5 nm settled)."""
from __future__ import annotations

import numpy as np

from hyst_model.effects.settle import settle, settle_result
from hyst_model.spec import build_model

CFG = {"dt": 5e-4, "u_scale": 15.0, "y_scale": 5.42e-6, "saturation.two_sided": 1.0}
T = np.arange(4000) * 5e-4
U = 75.0 + 40.0 * np.sin(2 * np.pi * 2.0 * T)  # the record
U_WIDE = 75.0 + 70.0 * np.sin(2 * np.pi * 2.0 * T)  # a wider excursion than the record's


def _model_and_theta(bottom_below_min: float):
    m = build_model("mbw", ["saturation"], CFG)
    names = [p.name for p in m.params()]
    th = np.array([p.default for p in m.params()], dtype=np.float64)
    nb = len(m.base.params())
    y = m.base.simulate(th[:nb], T, U)
    assert np.ptp(y) > 5e-6  # the defaults make a stage that moves
    top = float(np.max(y)) + 0.05e-6  # a knee the record enters at the top
    th[names.index("saturation.top")] = top
    th[names.index("saturation.width")] = 0.3e-6
    th[names.index("saturation.bottom")] = float(np.min(y)) - 0.3e-6 - bottom_below_min
    return m, th, names


def test_an_unreached_lower_stop_moves_out_and_the_record_is_unchanged_bit_for_bit():
    m, th, names = _model_and_theta(0.01e-6)  # the lower knee just below the record's lowest output
    s = settle(m, th, T, U)
    assert np.array_equal(m.simulate(s, T, U), m.simulate(th, T, U))
    ib = names.index("saturation.bottom")
    assert s[ib] < th[ib] - 1e-4 and s[names.index("saturation.top")] == th[names.index("saturation.top")]
    lo, hi = m.bounds
    assert lo[ib] < s[ib]  # not on its bound: that would be reported as a fit stuck there
    wide_fit, wide_settled = m.simulate(th, T, U_WIDE), m.simulate(s, T, U_WIDE)
    assert np.min(wide_fit) > np.min(wide_settled) + 1e-6  # the phantom stop clipped the wider excursion
    assert np.array_equal(settle(m, s, T, U), s)  # settled once is settled


def test_a_stop_the_record_reaches_stays_where_it_was_fitted():
    m, th, _ = _model_and_theta(-0.2e-6)  # the lower knee inside the record's range
    assert np.array_equal(settle(m, th, T, U), th)
    one = build_model("mbw", ["saturation"], {**CFG, "saturation.two_sided": 0.0})  # top only: nothing to settle
    assert np.array_equal(settle(one, th, T, U), th)
    base = build_model("mbw", [], CFG)
    nb = len(base.params())
    assert np.array_equal(settle(base, th[:nb], T, U), th[:nb])


def test_a_fit_result_is_settled_with_its_named_parameters():
    from hyst_model.identify.result import FitResult
    m, th, names = _model_and_theta(0.01e-6)
    res = FitResult(model=m.name, method="fast", params=m.unpack(th), theta=th, rmse_train=1e-9, rmse=1e-9,
                    seconds=0.0, n_evaluations=0, n_iterations=0, residuals=np.zeros(T.size), split="")
    out = settle_result(m, res, T, U)
    assert out.params["saturation.bottom"] == out.theta[names.index("saturation.bottom")] < th[names.index(
        "saturation.bottom")]
    assert out.rmse == res.rmse and settle_result(m, out, T, U) is out
