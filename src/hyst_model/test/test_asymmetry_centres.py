"""The quadratic asymmetry's centres are configuration: a model composed again from the diagnosis's configuration
reads its fitted parameters about the same centres, so a rung's own parameters reproduce the rung and the guard
of :func:`guarded_refit` compares against the right start."""
import numpy as np
import pytest

from hyst_model.diagnose.refit import _point, _scales, guarded_refit, refit, rmse, validation_mask
from hyst_model.effects import compose, effects_data_config
from hyst_model.effects.asymmetry import Asymmetry
from hyst_model.identify import fit
from hyst_model.spec import build_model


def _record(seed: int = 5):
    """A unipolar piezo-like MBW record (steps and sines well away from 0 V) with a planted even term and a
    linear drift: the centres of the quadratic are far from zero."""
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(6000) * dt
    u = 75.0 + 50.0 * np.sin(2 * np.pi * 1.3 * t) * (0.6 + 0.4 * np.sin(2 * np.pi * 0.11 * t))
    cfg = dict(_scales(u, 2e-7 * u), dt=dt)
    base = build_model("mbw", (), cfg)
    x = base.simulate(base.theta0, t, u)
    xc = 0.5 * (x.min() + x.max())
    y = x + 0.04 * (x - xc) ** 2 / cfg["y_scale"] + 2e-8 * t / t[-1] + rng.normal(0.0, 2e-9, t.size)
    return t, u, y


def test_data_config_holds_the_centres_and_start_keeps_configured_ones():
    t, u, y = _record()
    val = validation_mask(t.size, u)
    dc = Asymmetry.data_config(t, u, y, ~val)
    assert dc["asymmetry.u_c"] == pytest.approx(0.5 * (u.min() + u.max()))
    assert dc["asymmetry.y_c"] == pytest.approx(0.5 * (y.min() + y.max()))
    cfg = dict(_scales(u, y), dt=1e-3, **{"asymmetry.u_c": 10.0, "asymmetry.y_c": 1e-6})
    a = Asymmetry(cfg)
    a.start(t, u, y, np.zeros_like(y))
    assert (a.u_c, a.y_c) == (10.0, 1e-6)  # configured centres are not replaced by the data's
    b = Asymmetry(dict(_scales(u, y), dt=1e-3))
    b.start(t, u, y, np.zeros_like(y))
    assert b.u_c == pytest.approx(dc["asymmetry.u_c"])  # without them, start centres on the data as before


def test_a_rung_composed_again_from_the_configuration_reproduces_itself_and_the_guard_never_goes_back():
    t, u, y = _record()
    val = validation_mask(t.size, u)
    cfg = dict(_scales(u, y), dt=1e-3)
    base = build_model("mbw", (), cfg)
    cfg.update(effects_data_config(["asymmetry", "drift"], t, u, y, ~val))
    th_b = fit(base, t, u, y, method="fast").theta
    m, th, yh = refit(base, ["asymmetry"], cfg, t, u, y, th_b)
    r_rung = rmse((y - yh)[val])
    again = compose(base, ["asymmetry"], cfg)
    th2 = _point(again, m.unpack(th))
    # Centres at 0 (the defect) read this rung at several times its error.
    assert rmse((y - again.simulate(th2, t, u))[val]) == pytest.approx(r_rung, rel=1e-9)
    m3, th3, yh3 = guarded_refit(base, ["asymmetry", "drift"], cfg, t, u, y, val, m.unpack(th),
                                 theta_base=m.split(th)[0], carry=m.unpack(th))
    assert rmse((y - yh3)[val]) <= r_rung * (1 + 1e-9)
