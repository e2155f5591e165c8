"""Thesis facts of ch. 3 on the discrete (3.19)/(3.21) and continuous (3.9) models, with the metrics defined here.

Reconstruction accuracy (Fig. 3.7): 1 − RMSE(y_discrete − y_continuous) / range(y_continuous).
Loop change with frequency (Fig. 3.8): the steady-state loop y(phase) of the last cycle, resampled on 200 input
phases, compared with the 1 Hz loop: RMS difference / range of the 1 Hz loop.
"""
import numpy as np
import pytest

from hyst_model.core import THESIS_FIG37, THESIS_FIG38, THESIS_TABLE41, mbw_simulate
from hyst_model.models import bw_bound, bw_special

DT = 5e-4  # Fig. 3.7/3.8: 0.5 ms sampling (2 kHz)


def _sine(f, cycles, fs=2000.0):
    k = np.arange(int(round(cycles * fs / f)) + 1)
    return k, 10.0 * np.sin(2 * np.pi * f * k / fs)


def _loop(p, f, fs=2000.0, cycles=3, nb=200):
    k, u = _sine(f, cycles, fs)
    y = mbw_simulate(p, u, 0.0, np.nan)
    last = k >= k[-1] - int(fs / f)
    ph = (2 * np.pi * f * k[last] / fs) % (2 * np.pi)
    o = np.argsort(ph)
    grid = np.linspace(0, 2 * np.pi, nb, endpoint=False)
    return np.interp(grid, ph[o], y[last][o], period=2 * np.pi)


def test_discrete_bw_reconstructs_continuous_bw_fig37():
    # (3.19) at 2 kHz vs the exact solution of (3.9) on a 10x finer grid, u = 10 sin(2 pi t), two cycles
    t = np.arange(int(2 / DT) + 1) * DT
    yd = mbw_simulate(THESIS_FIG37.vector, 10 * np.sin(2 * np.pi * t), 0.0, np.nan)
    tf = np.arange(int(2 / DT) * 10 + 1) * DT / 10
    yc = bw_special(0.5, 0.02, -0.05, 10 * np.sin(2 * np.pi * tf))[::10]
    accuracy = 1 - np.sqrt(np.mean((yd - yc) ** 2)) / np.ptp(yc)
    assert accuracy >= 0.97  # thesis: "about 97 %"; measured 0.990
    # and the match is not trivial: a wrong δ breaks it
    ybad = mbw_simulate(THESIS_FIG37.replace(delta1=0.99).vector, 10 * np.sin(2 * np.pi * t), 0.0, np.nan)
    assert 1 - np.sqrt(np.mean((ybad - yc) ** 2)) / np.ptp(yc) < 0.9


def test_bw_loops_keep_their_shape_with_frequency_but_mbw_loops_change_fig38():
    bw = THESIS_FIG38.replace(zeta2=0.0, psi2=0.0, alpha2=0.0).vector
    mbw = THESIS_FIG38.vector
    change = {}
    for name, p in (("bw", bw), ("mbw", mbw)):
        ref = _loop(p, 1.0)
        change[name] = [np.sqrt(np.mean((_loop(p, f) - ref) ** 2)) / np.ptp(ref) for f in (10.0, 25.0, 50.0)]
    # BW: only the per-sample δ relaxation and the coarser sampling at 50 Hz move the loop (measured ≤ 2.4 %)
    assert max(change["bw"]) < 0.03
    # MBW: the rate terms reshape it, more the faster the input (measured 4 %, 8 %, 14 %)
    assert change["mbw"][2] > 0.10 and change["mbw"][2] > 4 * change["bw"][2]
    assert change["mbw"][0] < change["mbw"][1] < change["mbw"][2]


def test_pure_bw_is_rate_independent_when_delta_is_one():
    p = THESIS_FIG38.replace(zeta2=0.0, psi2=0.0, alpha2=0.0, delta1=1.0, delta2=1.0).vector
    ref = _loop(p, 1.0)
    assert np.sqrt(np.mean((_loop(p, 10.0) - ref) ** 2)) / np.ptp(ref) < 0.005


@pytest.mark.parametrize("params", [THESIS_FIG37, THESIS_FIG38, THESIS_TABLE41], ids=["fig37", "fig38", "tab41"])
@pytest.mark.parametrize("f", [1.0, 10.0, 50.0])
def test_thesis_parameter_sets_give_bounded_loops_for_the_pm10_sine(params, f):
    _, u = _sine(f, 5)
    y = mbw_simulate(params.vector, u, 0.0, np.nan)
    assert np.all(np.isfinite(y))
    assert np.max(np.abs(y)) < 10.0  # measured 5.1–7.5 model units
    # a real loop: the output spans a good part of the input range and is not single-valued
    assert np.ptp(y) > 4.0
    up = np.diff(u) > 0
    mid = np.abs(u[1:]) < 0.5
    # two branches: at u ≈ 0 the ascending and descending outputs differ by a visible loop width
    assert abs(np.mean(y[1:][up & mid]) - np.mean(y[1:][~up & mid])) > 0.01 * np.ptp(y)  # Table 4.1 at 1 Hz: 1.7 %


def test_nu_convention_absorbed_dt_is_bounded_literal_dt_diverges():
    """hyst uses ν_k = u_k − δ2·u_{k−1} (Δt absorbed); the literal (3.18) ν/Δt with Fig. 3.7 values diverges."""
    p = THESIS_FIG37.vector
    t = np.arange(4000) * DT
    u = 10 * np.sin(2 * np.pi * t)
    assert np.all(np.isfinite(mbw_simulate(p, u, 0.0, np.nan)))
    y, up, diverged = 0.0, u[0], False
    with np.errstate(all="ignore"):
        for k in range(u.size):
            nu = (u[k] - p[7] * up) / DT
            y = p[6] * y + p[0] * nu - p[2] * abs(nu) * y - p[4] * nu * abs(y)
            up = u[k]
            if not np.isfinite(y) or abs(y) > 1e6:
                diverged = True
                break
    assert diverged
    # the library's recursion takes ν_k = u_k − δ2·u_{k−1} (no Δt): from y = 0 one step is (ζ1 + ζ2·|Δu|)·ν_k
    from hyst_model.core import mbw_step
    for uk, up in ((3.0, 1.0), (-2.0, 4.0), (0.5, 0.5)):
        nu = uk - p[7] * up
        assert mbw_step(p, 0.0, uk, up) == pytest.approx((p[0] + p[1] * abs(uk - up)) * nu, rel=1e-12)


@pytest.mark.parametrize("xi,phi,gamma", [(0.85, 0.5, 0.115), (0.8, 0.035, 0.003), (1.0, 0.2, 0.5),
                                          (0.5, 0.3, -0.1)])
def test_bound_3_10_holds_for_random_inputs(xi, phi, gamma):
    rng = np.random.default_rng(3)
    u = np.cumsum(rng.normal(0, 1.0, 20000))  # wandering input with many reversals (minor loops) ...
    u = np.concatenate([u, u[-1] + np.linspace(0, 400, 4000)])  # ... then a long ramp that saturates y
    y = bw_special(xi, phi, gamma, u)
    bound = bw_bound(xi, phi, gamma)
    assert np.max(np.abs(y)) <= bound * (1 + 1e-9)
    assert np.max(np.abs(y)) > 0.9 * bound  # the bound is tight: large excursions approach it


def test_bound_3_10_is_not_a_bound_when_phi_plus_gamma_negative():
    assert bw_bound(0.5, 0.02, -0.05) == np.inf
