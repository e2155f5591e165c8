"""ComposedModel.simulate_jac: the base's exact sensitivities through the effects, checked against differences."""
import numpy as np
import pytest

from hyst_model.core.params import THESIS_TABLE41
from hyst_model.core.sensitivity import mbw_rest_state_sens, mbw_simulate_sens
from hyst_model.effects import EFFECTS, ComposedModel, compose
from hyst_model.effects.creep import _lag_bank
from hyst_model.effects.compose import Frozen
from hyst_model.effects.signals import sample_time
from hyst_model.identify.base import TrainProblem
from hyst_model.identify.result import Split
from hyst_model.model import MBWModel

CFG = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 1e-3}
VALUES = {"delay.tau": 1.3e-3, "creep.gain": 0.02, "creep.tilt": 0.1, "asymmetry.a_u": 0.05,
          "asymmetry.a_y": 0.02, "asymmetry.slope": 0.05, "asymmetry.level": 1e-5, "saturation.width": 2e-6,
          "saturation.top": 1.2e-5, "drift.c1": 3e-9, "drift.c3": -2e-9, "dynamics.fn": 300.0,
          "dynamics.zeta": 0.05, "dynamics.part": 0.3, "dynamics.lag": 0.4, "creep.tau1": 0.05,
          "creep.tau2": 1.2, "creep.share": 0.6}


def _record(n=4000):
    t = np.arange(n) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * 2 * t) + np.where(t > 2.0, 5.0, 0.0)
    return t, u


def _model(names, extra=None):
    m = compose(MBWModel(u_scale=CFG["u_scale"], y_scale=CFG["y_scale"]), names, {**CFG, **(extra or {})})
    th = m.theta0.copy()
    th[:8] = list(THESIS_TABLE41.vector)
    th[8] = 2e-8  # offset
    for k, v in VALUES.items():
        if k in m.names:
            th[m.names.index(k)] = v
    lo, hi = m.bounds
    return m, np.clip(th, lo, hi)


STACKS = [(["delay", "creep", "asymmetry", "saturation", "drift"], {}),
          (["delay", "dynamics", "creep"], {}),
          (["dynamics"], {"dynamics.hold": "foh"}),
          (["creep", "delay"], {"delay.side": "output"}),
          (["asymmetry"], {"asymmetry.form": "kink"}),
          (["saturation", "creep"], {"saturation.two_sided": 1.0}),
          (["delay", "creep"], {"creep.form": "lags"})]


@pytest.mark.parametrize("names,extra", STACKS, ids=["+".join(s[0]) for s in STACKS])
def test_the_jacobian_matches_central_differences_column_by_column(names, extra):
    t, u = _record()
    m, th = _model(names, extra)
    assert m.jac_available
    y, J = m.simulate_jac(th, t, u)
    np.testing.assert_array_equal(y, m.simulate(th, t, u))
    lo, hi = m.bounds
    for i in range(th.size):
        h = 1e-5 * max(abs(th[i]), 1e-3 * (hi[i] - lo[i]))
        a, b = th.copy(), th.copy()
        a[i] += h
        b[i] -= h
        c = (m.simulate(a, t, u) - m.simulate(b, t, u)) / (2 * h)
        scale = np.linalg.norm(c)
        assert np.linalg.norm(J[:, i] - c) <= 1e-4 * scale + 1e-30, m.names[i]


def test_mbw_jacobian_matches_central_differences():
    """The MBW's forward sensitivities (core/sensitivity.py), in the model's layout and scale, with the offset."""
    t, u = _record()
    m = MBWModel(u_scale=15.0, y_scale=5.42e-6)
    th = m.theta0.copy()
    th[:8] = list(THESIS_TABLE41.vector)
    th[-1] = 1e-7
    y, J = m.simulate_jac(th, t, u)
    np.testing.assert_array_equal(y, m.simulate(th, t, u))
    np.testing.assert_array_equal(J[:, -1], 1.0)
    lo, hi = m.bounds
    for i in range(th.size - 1):
        h = 1e-6 * max(abs(th[i]), 1e-3 * (hi[i] - lo[i]))
        a, b = th.copy(), th.copy()
        a[i] += h
        b[i] -= h
        c = (m.simulate(a, t, u) - m.simulate(b, t, u)) / (2 * h)
        assert np.linalg.norm(J[:, i] - c) <= 1e-4 * np.linalg.norm(c), m.names[i]
    _, S = mbw_simulate_sens(m.to_params(th).vector, np.ascontiguousarray(u / 15.0), *mbw_rest_state_sens(
        m.to_params(th).vector, u[0] / 15.0))
    np.testing.assert_array_equal(J[:, :-1], m.y_scale * S)  # the unscaled recursion is the same numbers


def test_structures_the_chain_rule_does_not_cover_fall_back_to_differences():
    base = MBWModel(u_scale=15.0, y_scale=5.42e-6)
    bw = MBWModel(u_scale=15.0, y_scale=5.42e-6, rate=False)
    for b, names, extra in ((base, ["dynamics"], {"dynamics.structure": "feedback"}),
                            (base, ["creep", "dynamics"], {"dynamics.structure": "feedback"}),
                            (bw, ["creep", "rate"], {})):
        m = compose(b, names, {**CFG, **extra})
        assert not m.jac_available
        t, u = _record(1500)
        assert not TrainProblem(m, t, u, np.zeros_like(t), Split(0, t.size, t.size, t.size, "all")).has_jac
    frozen = ComposedModel(base, [Frozen(EFFECTS["creep"](CFG), [0.01, 0.0])])
    assert not frozen.jac_available  # overrides apply(): its output is not what output() says
    m, _ = _model(["delay", "creep"])
    t, u = _record(1500)
    assert TrainProblem(m, t, u, np.zeros_like(t), Split(0, t.size, t.size, t.size, "all")).has_jac


@pytest.mark.parametrize("form,th", [("log", [0.03, -0.2]), ("lags", [0.05, 0.04, 0.9, 0.7])])
def test_creeps_own_push_is_its_operator_on_each_column(form, th):
    c = EFFECTS["creep"]({"dt": 1e-3, "creep.form": form})
    t = np.arange(6000) * 1e-3
    J = np.random.default_rng(3).normal(size=(t.size, 5)).cumsum(axis=0)
    th = np.array(th)
    pushed = c.push(th, t, None, np.sin(t), None, J)
    each = np.column_stack([c.output(th, t, None, np.ascontiguousarray(J[:, k])) for k in range(J.shape[1])])
    np.testing.assert_allclose(pushed, each, rtol=0, atol=1e-12 * np.max(np.abs(each)))
    # and the fused kernel is the operator's array expression J − g (J − L) to the last bit (L: each column's bank)
    g, taus, w = c.bank(th)
    a = np.exp(-sample_time(t) / taus)
    L = np.column_stack([_lag_bank(np.ascontiguousarray(J[:, k]), a, w) for k in range(J.shape[1])])
    np.testing.assert_array_equal(pushed, J - g * (J - L))


def test_a_fit_with_the_exact_jacobian_recovers_a_known_model(monkeypatch):
    """Data from mbw + delay + creep + asymmetry with known values and 2 nm noise, fitted from the base's values
    with the effects at their defaults: the error reaches the noise, the creep is found, and the fit with
    differences of the whole model (as before) ends at the same error."""
    from hyst_model import identify
    rng = np.random.default_rng(11)
    t = np.arange(8000) * 5e-4
    u = 75 - 70 * np.cos(2 * np.pi * 1.5 * t) * np.exp(-0.2 * t) + 10 * (t > 2.0)
    m, th_true = _model(["delay", "creep", "asymmetry"])
    y = m.simulate(th_true, t, u) + 2e-9 * rng.standard_normal(t.size)
    th0 = m.theta0.copy()
    th0[:9] = th_true[:9]
    res = identify.fit(m, t, u, y, method="fast", theta0=th0, max_nfev=80)
    assert res.rmse < 1.1 * 2e-9, res.rmse
    assert abs(res.params["creep.gain"] - VALUES["creep.gain"]) < 0.1 * VALUES["creep.gain"]
    monkeypatch.setattr(ComposedModel, "jac_available", property(lambda self: False))
    fd = identify.fit(m, t, u, y, method="fast", theta0=th0, max_nfev=80)
    assert abs(res.rmse - fd.rmse) < 0.01 * fd.rmse
