"""ComposedModel reuses unchanged inner stages within a Jacobian: exactly the same numbers, fewer base simulations,
nothing kept afterwards."""
import pickle

import numpy as np
import pytest

from hyst_model.core.params import THESIS_TABLE41
from hyst_model.effects import Effect, compose
from hyst_model.model import MBWModel

CFG = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 1e-3}


def _record(n=2000):
    t = np.arange(n) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * 2 * t) + np.where(t > 1.0, 5.0, 0.0)
    return t, u


def _point(m):
    th = m.theta0.copy()
    th[:8] = list(THESIS_TABLE41.vector)
    vals = {"delay.tau": 1.3e-3, "creep.gain": 0.02, "creep.tilt": 0.1, "asymmetry.a_u": 0.05,
            "asymmetry.a_y": 0.02, "asymmetry.slope": 0.05, "saturation.width": 2e-6, "drift.c1": 3e-9,
            "dynamics.fn": 300.0, "dynamics.zeta": 0.05, "dynamics.part": 0.1}
    for k, v in vals.items():
        if k in m.names:
            th[m.names.index(k)] = v
    lo, hi = m.bounds
    return np.clip(th, lo, hi)


class _Counting(MBWModel):
    calls = 0

    def simulate(self, theta, t, u):
        type(self).calls += 1
        return super().simulate(theta, t, u)


def _base():
    return _Counting(u_scale=CFG["u_scale"], y_scale=CFG["y_scale"])


STACKS = [["delay", "creep", "asymmetry", "saturation", "drift"],
          ["dynamics", "creep"],
          ["creep", "dynamics", "delay"]]


@pytest.mark.parametrize("names", STACKS, ids=["+".join(s) for s in STACKS])
def test_every_single_parameter_step_gives_exactly_a_fresh_models_output(names):
    t, u = _record()
    m = compose(_base(), names, CFG)
    th = _point(m)
    with m.reusing_stages():
        y0 = m.simulate(th, t, u)
        for i in reversed(range(th.size)):  # the order of a finite-difference Jacobian
            tp = th.copy()
            tp[i] += 1e-4 * max(abs(tp[i]), 1e-3)
            fresh = compose(_base(), names, CFG)  # no stage remembered
            np.testing.assert_array_equal(m.simulate(tp, t, u), fresh.simulate(tp, t, u), err_msg=m.names[i])
        np.testing.assert_array_equal(m.simulate(th, t, u), y0)
        # another input is another record: nothing reused from the last one
        u2 = u[::-1].copy()
        np.testing.assert_array_equal(m.simulate(th, t, u2), compose(_base(), names, CFG).simulate(th, t, u2))


def test_an_outer_parameter_step_does_not_simulate_the_base_again():
    t, u = _record()
    m = compose(_base(), ["delay", "creep", "saturation"], CFG)
    th = _point(m)
    with m.reusing_stages():
        m.simulate(th, t, u)
        _Counting.calls = 0
        for k in ("creep.gain", "creep.tilt", "saturation.width"):
            tp = th.copy()
            tp[m.names.index(k)] *= 1.01
            m.simulate(tp, t, u)
        assert _Counting.calls == 0
        tp = th.copy()
        tp[m.names.index("delay.tau")] *= 1.01  # inside: the base sees another input
        m.simulate(tp, t, u)
        assert _Counting.calls == 1
        tp[0] *= 1.01  # a base parameter: everything again
        m.simulate(tp, t, u)
        assert _Counting.calls == 2
    # outside a Jacobian nothing is remembered: a model kept for later holds no copies of the record
    assert "_memo" not in m.__dict__
    _Counting.calls = 0
    m.simulate(th, t, u)
    m.simulate(th, t, u)
    assert _Counting.calls == 2


class _InPlace(Effect):
    """An output effect that writes into its inner output (allowed): a reused stage must not see that."""

    name = "inplace_test"
    kind = "output"

    def params(self):
        from hyst_model.model import Param
        return (Param("k", 0.0, -1.0, 1.0, "", ""),)

    def output(self, theta, t, u, y):
        y *= 1.0 + theta[0]
        return y


class _Wrap(Effect):
    """A user's effect of kind wrap: sees the inner structure, so only differences of the whole model apply."""

    name = "wrap_test"
    kind = "wrap"

    def params(self):
        from hyst_model.model import Param
        return (Param("k", 0.0, -1.0, 1.0, "", ""),)

    def apply(self, theta, t, u, inner):
        return inner(t, u) * (1.0 + theta[0])


def test_an_effect_working_in_place_on_its_inner_output_cannot_corrupt_a_reused_stage():
    from hyst_model.effects.base import ComposedModel
    from hyst_model.effects import EFFECTS
    t, u = _record()
    inner = EFFECTS["creep"](CFG)
    m = ComposedModel(_base(), [inner, _InPlace(CFG), EFFECTS["saturation"](CFG)])
    th = _point(m)
    th[m.names.index("inplace_test.k")] = 0.5
    y0 = m.simulate(th, t, u).copy()
    with m.reusing_stages():
        for _ in range(3):  # its own parameter stepped: the creep stage inside it is reused each time
            tp = th.copy()
            tp[m.names.index("inplace_test.k")] *= 1.0 + 1e-6
            m.simulate(tp, t, u)
            np.testing.assert_array_equal(m.simulate(th, t, u), y0)


def test_a_model_pickled_within_a_jacobian_leaves_its_stages_behind_and_simulates_the_same():
    t, u = _record()
    m = compose(_base(), ["delay", "creep"], CFG)
    th = _point(m)
    with m.reusing_stages():
        y0 = m.simulate(th, t, u)
        blob = pickle.dumps(m)
    assert len(blob) < 50_000  # no remembered signals (each stage holds ~3 x 16 kB here)
    np.testing.assert_array_equal(pickle.loads(blob).simulate(th, t, u), y0)


def test_a_finite_difference_jacobian_simulates_the_base_once_per_base_parameter_and_once_more():
    """A structure the chain rule does not cover (an effect of kind wrap) takes differences of the whole model:
    the effects' columns reuse the base simulated at θ."""
    from hyst_model.effects import EFFECTS
    from hyst_model.effects.base import ComposedModel
    from hyst_model.identify.base import TrainProblem
    from hyst_model.identify.result import Split
    t, u = _record()
    m = ComposedModel(_base(), [_Wrap(CFG), EFFECTS["creep"](CFG)])
    assert not m.jac_available
    th = _point(m)
    p = TrainProblem(m, t, u, m.simulate(th, t, u), Split(0, t.size, t.size, t.size, "all"))
    p.residuals(th)  # the point LM accepted: its residuals are cached, as in a fit
    _Counting.calls = 0
    _, J = p.fd_residuals_jac(th)
    n_base = len(m.base.names)
    assert _Counting.calls == n_base + 1, (_Counting.calls, len(m.names))
    assert np.all(np.isfinite(J)) and np.all(np.any(J[:, n_base:] != 0, axis=0))
    assert "_memo" not in m.__dict__
