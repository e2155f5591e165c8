"""Continuous-time DEB models (3.1), (3.6), (3.9), (2.24)–(2.25) against independent integrations and closed forms."""
import numpy as np
import pytest

from hyst_model.models import backlash_like, bw_general, bw_special, dahl


def _euler(rhs, u, y0=0.0, sub=200):
    """Reference: explicit Euler in the input domain with many sub-steps per input interval."""
    y = np.empty(u.size)
    yk = y0
    y[0] = yk
    for k in range(1, u.size):
        du = (u[k] - u[k - 1]) / sub
        s = np.sign(u[k] - u[k - 1])
        uu = u[k - 1]
        for _ in range(sub):
            yk += rhs(yk, uu, s) * du
            uu += du
        y[k] = yk
    return y


U = 10 * np.sin(2 * np.pi * np.linspace(0, 2, 401))


def test_backlash_like_matches_numerical_integration():
    a, b, c = 0.5, 0.85, 0.115
    y = backlash_like(a, b, c, U)
    ref = _euler(lambda y, u, s: b - a * s * y + c * s * u, U)
    np.testing.assert_allclose(y, ref, atol=5e-3 * np.ptp(ref))


def test_backlash_like_asymptote_3_4():
    a, b, c = 0.5, 0.85, 0.115
    u = np.linspace(0, 60, 601)
    y = backlash_like(a, b, c, u)
    assert abs((y[-1] - c / a * u[-1]) - (a * b - c) / a ** 2) < 1e-9


def test_dahl_closed_form_3_7_and_limit_3_8():
    alpha, beta = 0.5, 0.85
    u = np.linspace(0, 5, 51)
    y = dahl(alpha, beta, u, y0=0.3)
    expected = 0.3 * np.exp(-alpha * u) + beta / alpha * (1 - np.exp(-alpha * u))
    np.testing.assert_allclose(y, expected, rtol=1e-12, atol=1e-12)
    assert abs(dahl(alpha, beta, np.linspace(0, 80, 9))[-1] - beta / alpha) < 1e-9


def test_bw_special_matches_numerical_integration_across_zero_crossings():
    xi, phi, gamma = 0.5, 0.02, -0.05
    y = bw_special(xi, phi, gamma, U)
    ref = _euler(lambda y, u, s: xi - phi * s * y - gamma * abs(y), U)
    np.testing.assert_allclose(y, ref, atol=5e-3 * np.ptp(ref))
    assert (np.diff(np.sign(y)) != 0).sum() >= 3  # the loop crosses zero, so the split logic is exercised


def test_general_bw_reduces_to_special_case_and_integrates_n2():
    np.testing.assert_allclose(bw_general(0.0, 1.0, 0.5, 0.02, -0.05, 1.0, U), bw_special(0.5, 0.02, -0.05, U))
    rho, k, xi, phi, gamma = 0.3, 2.0, 1.0, 0.4, 0.2
    y = bw_general(rho, k, xi, phi, gamma, 2.0, U, substeps=8)
    w = _euler(lambda w, u, s: xi - phi * s * abs(w) * w - gamma * w * w, U)
    np.testing.assert_allclose(y, rho * k * U + (1 - rho) * k * w, atol=5e-3 * np.ptp(y))


def test_general_bw_rejects_n_below_one():
    with pytest.raises(ValueError):
        bw_general(0.5, 1.0, 1.0, 0.5, 0.1, 0.5, U)
