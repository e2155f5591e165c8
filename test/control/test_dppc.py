"""DPPC (4.7)–(4.21): known answers on a perfect model, and never NaN/wild under noise, bumps, bad models."""
import math

import numpy as np
import pytest

from hyst_control.base import invert_nu, mu_select
from hyst_control.dppc import DPPC, DPPCGains
from hyst_common.limits import CommandLimits
from hyst_bringup.loop import default_plant, run_closed_loop
from hyst_model.core import THESIS_TABLE41, mbw_rest_state, mbw_step, pea_default

WIDE = CommandLimits(-1e6, 1e6, math.inf, 0.0)


class ExactPlant:
    """Noise-free MBW plant in model units (y_scale = u_scale = 1) for the known-answer tests."""

    def __init__(self, model, u0=0.0):
        self.p = model.vector
        self.u = u0
        self.y = mbw_rest_state(self.p, u0)

    def step(self, u):
        self.y = mbw_step(self.p, self.y, u, self.u)
        self.u = u
        return self.y


def test_transformed_error_contracts_by_chi_4_21():
    """With a perfect model and the exact rate, (4.17) holds: e_k = λ_k·tanh(χ·ε_{k−1}) for h = h̄ = 1,
    and (4.21): ε_k = χ·ε_{k−1}."""
    m = THESIS_TABLE41
    g = DPPCGains(lambda0=20.0, lambda_inf=0.4, omega=0.01, chi=0.1)
    c = DPPC(m, 5e-4, g, WIDE)
    plant = ExactPlant(m)
    y = plant.y
    r = 4.0
    c.reset(y, 0.0, r0=r)  # e0 = y0 - r
    eps_prev = c.state()["epsilon"]  # ε_0 of Step 0 (4.9)
    lam = 20.0
    for k in range(30):
        u = c.step(r, y)  # uses ε_{k−1}, computed from the newest measurement (4.10)
        eps = c.state()["epsilon"]
        if k > 0:
            assert eps == pytest.approx(0.1 * eps_prev, rel=1e-9, abs=1e-15)  # (4.21)
        y = plant.step(u)
        lam = 0.99 * lam + 0.01 * 0.4
        assert c.state()["lambda"] == pytest.approx(lam, rel=1e-12)  # (4.7)
        assert y - r == pytest.approx(lam * math.tanh(0.1 * eps), abs=1e-12)  # (4.17)
        eps_prev = eps
    assert abs(y - r) < 1e-12


def test_mu_selection_matches_4_15_4_16_and_is_positive_under_remark_41():
    p = THESIS_TABLE41.vector
    z1, z2, ps1, ps2, a1, a2 = p[:6]
    rng = np.random.default_rng(1)
    for y, ru in rng.uniform([-8, 0], [8, 3], size=(200, 2)):
        s = math.copysign(1.0, y)
        mp = z1 - abs(y) * (ps1 * s + a1) + (z2 - abs(y) * (ps2 * s + a2)) * ru
        mm = z1 + abs(y) * (ps1 * s - a1) + (z2 + abs(y) * (ps2 * s - a2)) * ru
        assert mu_select(p, y, ru, True, 1e-9) == pytest.approx(mp, rel=1e-12)
        assert mu_select(p, y, ru, False, 1e-9) == pytest.approx(mm, rel=1e-12)
        assert mp >= z1 and mm >= z1  # Remark 4.1 holds for Table 4.1


def test_exact_inversion_reproduces_the_model():
    """invert_nu(exact) solves ν·μ(ν, v_u) = y_r with v_u = |u_k − u_{k−1}|: mbw_step confirms it."""
    p = np.array([0.4346, 1e-6, 0.0345, 0.09, -0.05, -0.09, 0.9995, 0.9995])
    rng = np.random.default_rng(2)
    for y_prev, u_prev, target in rng.uniform([-6, -10, -8], [6, 10, 8], size=(300, 3)):
        y_r = target - p[6] * y_prev
        nu = invert_nu(p, y_prev, y_r, u_prev, 0.0, True, 1e-6)
        u = p[7] * u_prev + nu
        assert mbw_step(p, y_prev, u, u_prev) == pytest.approx(target, abs=1e-9)


@pytest.mark.parametrize("model", [pea_default(), pea_default().replace(alpha1=0.05, alpha2=0.03)],
                         ids=["table41", "violates-remark-4.1"])
def test_never_nan_with_noise_bumps_and_bad_samples(model):
    """Heavy noise, 5 µm bumps, NaN/inf samples: the funnel re-initialises, commands stay finite and in range."""
    rng = np.random.default_rng(3)
    c = DPPC(model, 5e-4)
    plant = default_plant(rate=2000.0, seed=3)
    y = plant.reset(0.0)
    c.reset(y, 0.0, 15e-6)
    us = []
    for k in range(3000):
        r = 15e-6 + 10e-6 * math.sin(2 * math.pi * 20 * k * 5e-4)
        meas = y + 50e-9 * rng.standard_normal()
        if k % 500 == 250:
            meas += 5e-6  # a bump far outside the λ∞ = 0.4 µm funnel
        if k % 777 == 5:
            meas = math.nan if k % 2 else math.inf
        u = c.step(r, meas)
        us.append(u)
        y = plant.step(u)
        s = c.state()
        assert all(math.isfinite(v) for v in s.values())
        assert abs(s["epsilon"]) <= 0.5 * math.log(1.9 / 0.1) + 1e-9
    us = np.array(us)
    assert np.all(np.isfinite(us)) and us.min() >= 0 and us.max() <= 150
    assert c.state()["funnel_resets"] >= 6
    assert c.state()["bad_inputs"] >= 3
    assert np.max(np.abs(np.diff(us))) <= 1e5 * 5e-4 + 1e-9


def test_out_of_funnel_step_recovers_to_noise_level():
    c = DPPC(pea_default(), 5e-4)
    res = run_closed_loop(c, "step", 0.5, plant=default_plant(2000.0), record=("lambda", "funnel_resets"))
    assert res.states["funnel_resets"][-1] >= 1  # the 15 µm step left the 0.75 µm funnel
    late = res.t > 0.2
    assert np.sqrt(np.mean((res.y - res.r)[late] ** 2)) < 10e-9


def test_bad_gains_rejected():
    from hyst_control.errors import ConfigError
    for kw in (dict(lambda0=1e-7), dict(omega=1.5), dict(chi=1.0), dict(h_lower=0), dict(funnel_margin=1)):
        with pytest.raises(ConfigError):
            DPPCGains(**kw)


def test_reference_rate_substitution_4_3_costs_accuracy_that_grows_with_frequency():
    """Thesis fact: replacing v_u by r_u (4.3) is an error source that grows with frequency; the exact input-rate
    inversion removes it (noise floor at every frequency)."""
    def rmse(f, exact):
        c = DPPC(pea_default(), 5e-4, DPPCGains(exact_rate=exact))
        return run_closed_loop(c, f"sine:{f}", 0.5, plant=default_plant(2000.0)).rmse

    thesis = [rmse(f, False) for f in (1, 10, 30)]
    exact = [rmse(f, True) for f in (1, 10, 30)]
    assert thesis[0] < thesis[1] < thesis[2] and thesis[2] > 3 * thesis[0]
    assert max(exact) < 1.2 * min(exact) and max(exact) < 4e-9
