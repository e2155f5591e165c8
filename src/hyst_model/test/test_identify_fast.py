"""The default identifier: recovery on seeded MBW data with sensor-like noise, splits, and any-model support."""
import numpy as np
import pytest

from hyst_model.core import pea_default
from hyst_model.errors import FitError
from hyst_model.identify import FastFit, LSQFit, fit, make_split
from hyst_model.model import Model, Param
from hyst_model.models import BASE_MODELS, data_config

TRUE = pea_default().replace(offset=-1.6e-6)
NOISE = 3e-9  # m RMS, plus 2 nm quantisation (the PEA sensor's resolution)


def _record(n=8000, seed=0, params=TRUE):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 5e-4
    f = rng.uniform(0.5, 20, 3)
    u = (75 + 40 * np.sin(2 * np.pi * f[0] * t) + 25 * np.sin(2 * np.pi * f[1] * t + 1)
         + 10 * np.sin(2 * np.pi * f[2] * t))
    y = params.simulate(u) + rng.normal(0, NOISE, n)
    return t, u, np.round(y / 2e-9) * 2e-9


def test_fast_recovers_mbw_parameters_and_reaches_the_noise_floor():
    t, u, y = _record()
    floor = np.sqrt(NOISE ** 2 + 2e-9 ** 2 / 12)
    model = BASE_MODELS["mbw"]({"u_scale": TRUE.u_scale, "y_scale": TRUE.y_scale, "offset_bound": 1e-4})
    est = FastFit(model).fit(t, u, y)
    res = est.result_
    assert res.rmse_train < 1.05 * floor and res.rmse < 1.05 * floor  # measured 1.00–1.01 x floor
    p = est.params_
    assert abs(p["zeta1"] - TRUE.zeta1) < 0.01 * TRUE.zeta1
    assert abs(p["delta1"] - TRUE.delta1) < 1e-3 and abs(p["delta2"] - TRUE.delta2) < 1e-3
    assert abs(p["psi1"] - TRUE.psi1) < 0.15 * TRUE.psi1 and abs(p["alpha1"] - TRUE.alpha1) < 0.15 * abs(TRUE.alpha1)
    assert abs(p["offset"] - TRUE.offset) < 5e-9
    assert res.residuals.shape == t.shape and res.n_evaluations > 0 and res.seconds > 0


@pytest.mark.slow
def test_fast_works_with_data_chosen_scaling_and_beats_the_fixed_start_lsq_or_ties():
    t, u, y = _record(seed=1)
    model = BASE_MODELS["mbw"](data_config(u, y))
    fast = fit(model, t, u, y)
    lsq = fit(model, t, u, y, method="lsq")
    assert fast.rmse < 1.1 * np.sqrt(NOISE ** 2 + 2e-9 ** 2 / 12)
    assert fast.rmse <= lsq.rmse * 1.01


def test_bw_model_fits_bw_data():
    true = TRUE.replace(zeta2=0.0, psi2=0.0, alpha2=0.0)
    t, u, y = _record(4000, seed=2, params=true)
    model = BASE_MODELS["bw"]({"u_scale": 15.0, "y_scale": 5.42e-6})
    res = fit(model, t, u, y)
    assert set(res.params) == {"zeta1", "psi1", "alpha1", "delta1", "delta2", "offset"}
    assert res.rmse < 1.1 * np.sqrt(NOISE ** 2 + 2e-9 ** 2 / 12)


def test_time_window_split_trains_only_on_the_window():
    t, u, y = _record(6000, seed=3)
    s = make_split(t, (0.5, 2.0))
    assert (s.train_start, s.train_stop, s.val_start, s.val_stop) == (1000, 4000, 4000, 6000)
    y_bad = y.copy()
    y_bad[4000:] += 1e-6  # corrupt the validation part only: the fit must not see it
    model = BASE_MODELS["mbw"](data_config(u, y))
    res = fit(model, t, u, y_bad, split=(0.5, 2.0))
    assert res.rmse_train < 2e-8 and 0.9e-6 < res.rmse < 1.1e-6
    with pytest.raises(FitError, match="holds only"):
        make_split(t, (10.0, 11.0))


class _Linear(Model):
    """A non-MBW model: y = a*u + b*u^3 + c (fits through scipy least_squares with finite differences)."""

    name = "cubic"

    def params(self):
        return (Param("a", 1.0, -10, 10), Param("b", 0.0, -1, 1), Param("c", 0.0, -1, 1))

    def simulate(self, theta, t, u):
        return theta[0] * u + theta[1] * u ** 3 + theta[2]


class _Composed(Model):
    """A base + effect model as the effects package builds them: base params first, effect params prefixed."""

    name = "mbw+gain"

    def __init__(self, base):
        self.base = base
        self.effects = ["gain"]

    def params(self):
        return self.base.params() + (Param("gain.k", 1.0, 0.5, 2.0),)

    def simulate(self, theta, t, u):
        return self.base.simulate(theta[:-1], t, u) * theta[-1]


def test_fast_fits_any_model_through_the_protocol():
    t = np.linspace(0, 1, 500)
    u = np.sin(7 * t) * 2
    y = 0.7 * u - 0.05 * u ** 3 + 0.1
    res = fit(_Linear(), t, u, y)
    np.testing.assert_allclose([res.params["a"], res.params["b"], res.params["c"]], [0.7, -0.05, 0.1], atol=1e-6)


@pytest.mark.slow
def test_composed_model_gets_the_equation_error_start_on_its_base():
    t, u, y = _record(1500, seed=4)
    base = BASE_MODELS["mbw"]({"u_scale": 15.0, "y_scale": 5.42e-6})
    comp = _Composed(base)
    est = FastFit(comp, n_starts=1, max_nfev=25).fit(t, u, y)
    assert est.result_.model == "mbw+gain"
    assert est.result_.rmse < 3e-8  # from the defaults alone least squares stalls far higher (checked below)
    lsq = LSQFit(comp, max_nfev=25).fit(t, u, y)
    assert lsq.result_.rmse > est.result_.rmse


def test_bad_data_is_a_fit_error():
    t, u, y = _record(100)
    y[3] = np.nan
    with pytest.raises(FitError, match="NaN"):
        fit(BASE_MODELS["mbw"]({}), t, u, y)
    with pytest.raises(FitError, match="does not vary"):
        fit(BASE_MODELS["mbw"]({}), t, np.zeros_like(u), np.nan_to_num(y))
    with pytest.raises(FitError, match="unknown method"):
        fit(BASE_MODELS["mbw"]({}), t, u, y, method="magic")


def test_a_repeated_base_fit_is_reused_with_the_same_result_and_a_changed_one_is_not():
    """A diagnosis refits the base MBW on the same (delayed) record many times: the fit is a pure function of its
    inputs, so a repeat returns the very numbers a new fit gives; any change in the record or the model refits."""
    t, u, y = _record(3000, seed=5)
    cfg = {"u_scale": TRUE.u_scale, "y_scale": TRUE.y_scale, "offset_bound": 1e-4}
    memo = FastFit.SOLVES
    first = FastFit(BASE_MODELS["mbw"](cfg)).fit(t, u, y).result_
    hits = memo.hits
    again = FastFit(BASE_MODELS["mbw"](cfg)).fit(t, u, y).result_
    assert memo.hits == hits + 1
    assert np.array_equal(again.theta, first.theta) and again.rmse == first.rmse
    assert again.n_iterations == first.n_iterations and again.n_evaluations == first.n_evaluations
    u2 = u.copy()
    u2[1000] += 1e-3  # one sample of the record
    FastFit(BASE_MODELS["mbw"](cfg)).fit(t, u2, y)
    FastFit(BASE_MODELS["mbw"]({**cfg, "y_scale": 2 * TRUE.y_scale})).fit(t, u, y)  # the model's configuration
    FastFit(BASE_MODELS["mbw"](cfg), max_nfev=30).fit(t, u, y)  # the fitter's budget
    assert memo.hits == hits + 1
    again.theta[0] = -1.0  # results handed out are copies: the remembered fit cannot be changed through them
    assert FastFit(BASE_MODELS["mbw"](cfg)).fit(t, u, y).result_.theta[0] == first.theta[0]
