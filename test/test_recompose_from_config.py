"""Every effect, in every configuration diagnose tries, is fully described by the diagnosis's configuration and
its parameter values: a model composed again from them reproduces the fitted one exactly.

The ladder, the refit guard, the other order, the prune and the exchange step all compose rungs again from the
configuration; an effect that kept a data-derived setting on one instance only (the quadratic asymmetry's centres
did) is read differently there, and the guard against refits that go backwards then compares against the wrong
start."""
import numpy as np
import pytest

from hyst_model.diagnose.refit import _point, _scales, default_fitter, refit, validation_mask
from hyst_model.effects import EFFECTS, compose, effects_data_config
from hyst_model.spec import build_model
from hyst_sim.generator import generate_case

NAMES = [n for n in sorted(EFFECTS) if n != "rate"]  # rate extends the BW base only


@pytest.fixture(scope="module")
def fitted_base():
    c = generate_case(1100169, "single_large")  # a unipolar piezo record: centres far from zero
    t, u, y = c.t[:6000], c.u[:6000], c.y[:6000]
    val = validation_mask(t.size, u)
    cfg = dict(_scales(u, y), dt=float(t[1] - t[0]))
    base = build_model("mbw", (), cfg)
    cfg.update(effects_data_config(NAMES, t, u, y, ~val))
    return t, u, y, cfg, base, default_fitter(base, t, u, y, None)


@pytest.mark.parametrize("name,variant", [(n, v) for n in NAMES
                                          for v in (getattr(EFFECTS[n], "variants", lambda: [{}])() or [{}])])
def test_a_fitted_effect_composed_again_from_the_configuration_is_the_same_model(fitted_base, name, variant):
    t, u, y, cfg, base, th_b = fitted_base
    cc = {**cfg, **variant}
    m, th, yh = refit(base, [name], cc, t, u, y, th_b)
    again = compose(base, [name], cc)
    np.testing.assert_array_equal(again.simulate(_point(again, m.unpack(th)), t, u), yh)
