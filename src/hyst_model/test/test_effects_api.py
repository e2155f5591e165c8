"""Effect API: composition, namespacing, identity defaults, overlap rules, rate = the thesis's BW → MBW step."""
import numpy as np
import pytest

from hyst_model.core.params import THESIS_TABLE41
from hyst_model.effects import EFFECTS, ComposedModel, Effect, compose
from hyst_model.effects.compose import Frozen, register
from hyst_model.errors import EffectError
from hyst_model.model import MBWModel, Param
from hyst_model.spec import build_model

MINE = ("creep", "asymmetry", "delay", "drift", "saturation")
CFG = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 1e-3}


def _record(n=3000):
    t = np.arange(n) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * 2 * t) + np.where(t > 2.0, 5.0, 0.0)
    return t, u


def _theta_base(model):
    th = model.pack(dict(zip(("zeta1", "zeta2", "psi1", "psi2", "alpha1", "alpha2", "delta1", "delta2"),
                             THESIS_TABLE41.vector)))
    return th


def test_registry_has_the_builtins():
    for name in MINE + ("rate",):
        assert name in EFFECTS and EFFECTS[name].name == name
        e = EFFECTS[name](CFG)
        assert e.summary and e.physics and e.kind in ("input", "output", "wrap", "base")


@pytest.mark.parametrize("name", MINE)
def test_defaults_are_the_identity_and_params_are_namespaced(name):
    base = MBWModel(**{k: CFG[k] for k in ("u_scale", "y_scale")})
    m = compose(base, [name], CFG)
    assert isinstance(m, ComposedModel) and m.base is base and m.effects[0].name == name
    extra = m.names[len(base.names):]
    assert extra and all(n.startswith(name + ".") for n in extra)
    t, u = _record()
    th = m.theta0.copy()
    th[: len(base.names)] = _theta_base(base)
    np.testing.assert_allclose(m.simulate(th, t, u), base.simulate(_theta_base(base), t, u), rtol=0, atol=1e-15)
    lo, hi = m.bounds
    assert np.all(lo <= m.theta0) and np.all(m.theta0 <= hi) and np.all(lo < hi)


def test_rate_on_bw_is_exactly_mbw():
    bw = build_model("bw", (), CFG)
    m = compose(bw, ["rate"], CFG)
    mbw = build_model("mbw", (), CFG)
    p = THESIS_TABLE41
    th = m.pack({"zeta1": p.zeta1, "psi1": p.psi1, "alpha1": p.alpha1, "delta1": p.delta1, "delta2": p.delta2,
                 "offset": 1e-7, "rate.zeta2": p.zeta2, "rate.psi2": p.psi2, "rate.alpha2": p.alpha2})
    th_mbw = mbw.pack(dict(p.to_dict(), offset=1e-7))
    t, u = _record()
    np.testing.assert_array_equal(m.simulate(th, t, u), mbw.simulate(th_mbw, t, u))
    # and the rate terms matter: switching them off changes the output
    th0 = th.copy()
    th0[-3:] = 0.0
    assert np.max(np.abs(m.simulate(th0, t, u) - m.simulate(th, t, u))) > 1e-9


def test_overlaps_and_unknown_names_are_refused_with_one_clear_message():
    mbw = build_model("mbw", (), CFG)
    with pytest.raises(EffectError, match="already part of the mbw base"):
        compose(mbw, ["rate"], CFG)
    with pytest.raises(EffectError, match="listed twice"):
        compose(mbw, ["creep", "delay", "creep"], CFG)
    with pytest.raises(EffectError, match="unknown effect 'crep'.*creep"):
        compose(mbw, ["crep"], CFG)
    with pytest.raises(EffectError, match="unknown effect"):
        build_model("mbw", ["nonsense"], CFG)


def test_order_first_effect_is_innermost_and_composition_flattens():
    base = build_model("mbw", (), CFG)
    m = compose(compose(base, ["delay"], CFG), ["creep"], CFG)
    assert m.base is base and [e.name for e in m.effects] == ["delay", "creep"]
    assert m.name == "mbw+delay+creep"
    assert m.config()["u_scale"] == 15.0


def test_frozen_effect_has_no_parameters_but_same_output():
    base = build_model("mbw", (), CFG)
    m = compose(base, ["delay"], CFG)
    th = np.concatenate([_theta_base(base), [0.004]])
    f = ComposedModel(base, [Frozen(m.effects[0], [0.004])])
    assert f.names == base.names
    t, u = _record()
    np.testing.assert_array_equal(f.simulate(th[:-1], t, u), m.simulate(th, t, u))


def test_register_rejects_non_effects_and_name_clashes():
    with pytest.raises(EffectError):
        register(int)

    class Creep2(Effect):
        name = "creep"

    with pytest.raises(EffectError, match="already exists"):
        register(Creep2)

    class NoName(Effect):
        pass

    with pytest.raises(EffectError, match="needs a class attribute name"):
        register(NoName)


def test_a_user_effect_composes_like_a_builtin():
    class Gain(Effect):
        name = "test_gain_effect"
        kind = "output"

        def params(self):
            return (Param("k", 1.0, 0.5, 2.0, "", "output gain"),)

        def output(self, theta, t, u, y):
            return theta[0] * y

    register(Gain, replace=True)
    try:
        base = build_model("mbw", (), CFG)
        m = build_model("mbw", ["test_gain_effect"], CFG)
        t, u = _record()
        th = np.concatenate([_theta_base(base), [1.5]])
        np.testing.assert_allclose(m.simulate(th, t, u), 1.5 * base.simulate(_theta_base(base), t, u))
    finally:
        EFFECTS.pop("test_gain_effect", None)
