"""The ``dynamics`` effect with two modes in cascade (``dynamics.modes: 2``): the operator against known answers,
its parameters in a params file, recovery from a record, and the diagnosis keeping it over one mode."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete, lfilter

from hyst_model.diagnose.setup import Candidate
from hyst_model.diagnose.stages import _screened
from hyst_model.effects.dynamics import DynamicsEffect, series_filter
from hyst_model.identify import fit
from hyst_model.diagnose.refit import validation_mask
from hyst_model.io.params_file import read_params, spec_from_model, write_params
from hyst_model.spec import build_model

DT = 5e-4
CFG = {"u_scale": 150.0, "y_scale": 1e-5, "dt": DT}


def _textbook(x: np.ndarray, fn: float, zeta: float, fn2: float | None = None, zeta2: float = 0.0) -> np.ndarray:
    """ω²/(s² + 2ζωs + ω²) — and a second mode after it — discretised as one system with scipy's ZOH (the input
    held over the period before each sample: one sample of delay), at rest at x[0]."""
    w = 2 * np.pi * fn
    num, den = [w * w], [1.0, 2 * zeta * w, w * w]
    if fn2 is not None:
        w2 = 2 * np.pi * fn2
        num, den = [w * w * w2 * w2], np.polymul(den, [1.0, 2 * zeta2 * w2, w2 * w2])
    nd, dd, _ = cont2discrete((num, den), DT, method="zoh")
    return x[0] + lfilter(np.ravel(nd), dd, x - x[0])


def _input(n: int, seed: int) -> np.ndarray:
    """Steps with holds and a band-limited random part: rings both modes and moves the hysteresis."""
    rng = np.random.default_rng(seed)
    steps = np.repeat(rng.uniform(20.0, 130.0, n // 400 + 1), 400)[:n]
    noise = lfilter([0.05], [1.0, -0.95], rng.normal(0.0, 10.0, n))
    return np.clip(steps + noise, 0.0, 150.0)


def test_two_modes_are_the_cascade_discretised_as_one_system():
    e = DynamicsEffect({**CFG, "dynamics.modes": 2})
    assert [p.name for p in e.params()] == ["fn", "zeta", "part", "lag", "fn2", "zeta2"]
    x = np.cumsum(np.random.default_rng(1).normal(size=3000)) * 1e-8
    t = np.arange(x.size) * DT
    # read a whole sample into the hold: scipy's ZOH of the fourth-order cascade
    tb = _textbook(x, 420.0, 0.04, 760.0, 0.06)
    th = np.array([420.0, 0.04, 1.0, 1.0, 760.0, 0.06])
    np.testing.assert_allclose(e.output(th, t, x, x), tb, rtol=0, atol=1e-14)
    # read at the end of the hold (the MBW's timing): the same response one sample earlier; participation 0.3
    th0 = np.array([420.0, 0.04, 0.3, 0.0, 760.0, 0.06])
    np.testing.assert_allclose(e.output(th0, t, x, x)[:-1], x[:-1] + 0.3 * (tb[1:] - x[:-1]), rtol=0, atol=1e-14)
    # it is not the two modes discretised one after the other (that puts one more sample between them)
    apart = _textbook(_textbook(x, 420.0, 0.04), 760.0, 0.06)
    assert np.max(np.abs(apart - tb)) > 1e4 * 1e-14  # far beyond the agreement above
    # one mode has none of the second's parameters, and its output is the one-mode filter
    e1 = DynamicsEffect(CFG)
    assert [p.name for p in e1.params()] == ["fn", "zeta", "part", "lag"]
    np.testing.assert_allclose(e1.output(th0[:4], t, x, x), x + 0.3 * (series_filter(x, 420.0, 0.04, DT, "zoh") - x),
                               rtol=0, atol=1e-20)
    np.testing.assert_allclose(e1.output(th[:4], t, x, x), _textbook(x, 420.0, 0.04), rtol=0, atol=1e-14)


def test_two_modes_round_trip_through_a_params_file(tmp_path):
    m = build_model("mbw", ["dynamics"], {**CFG, "dynamics.modes": 2})
    th = m.theta0.copy()
    th[m.names.index("dynamics.fn2")] = 640.0
    p = tmp_path / "two.yaml"
    write_params(p, spec_from_model(m, th, dt=DT))  # as hyst fit writes it (without dt: read at 1 kHz, refused)
    spec = read_params(p)
    assert float(spec.config["dynamics.modes"]) == 2.0 and spec.values["dynamics.fn2"] == pytest.approx(640.0)
    m2 = spec.model()
    t = np.arange(2000) * DT
    u = _input(t.size, 3)
    np.testing.assert_array_equal(m2.simulate(spec.theta(m2), t, u), m.simulate(th, t, u))


def test_two_modes_are_recovered_from_a_record_one_mode_cannot_fit():
    """A stage with two lightly damped modes (480 and 840 Hz) on a tenth of the motion: the two-mode fit reaches
    the noise and finds both; one mode stays several times above it."""
    n = 8000
    t = np.arange(n) * DT
    u = _input(n, 7)
    base = build_model("mbw", [], CFG)
    x = base.simulate(base.theta0, t, u)
    clean = x + 0.1 * (_textbook(x, 480.0, 0.05, 840.0, 0.05) - x)
    noise = 0.002 * np.std(clean)
    y = clean + np.random.default_rng(11).normal(0.0, noise, n)
    val = validation_mask(n, u)
    out = {}
    for modes in (1, 2):
        m = build_model("mbw", ["dynamics"], {**CFG, "dynamics.modes": modes})
        eff = m.effects[-1]
        th0 = m.theta0.copy()
        th0[:len(base.theta0)] = base.theta0
        e0 = y - base.simulate(base.theta0, t, u)
        for k, v in eff.start(t, u, y, e0).items():
            th0[m.names.index(f"dynamics.{k}")] = v
        r = fit(m, t, u, y, method="fast", split=val, theta0=th0)
        e = y - m.simulate(r.theta, t, u)
        out[modes] = (float(np.sqrt(np.mean(e[val] ** 2))) / noise, dict(zip(m.names, r.theta)))
    assert out[2][0] < 1.3, out[2][0]
    assert out[1][0] > 2.0 * out[2][0], (out[1][0], out[2][0])
    found = sorted((out[2][1]["dynamics.fn"], out[2][1]["dynamics.fn2"]))
    assert found == pytest.approx([480.0, 840.0], rel=0.03)


def test_the_runner_up_configuration_is_kept_for_a_joint_refit():
    """Screens with the base held fixed rank configurations; the second best is handed on to be refitted too,
    unless its screen already was a joint refit or failed."""
    class S:  # the parts of Setup _screened reads
        base, base_val, min_factor, noise_margin, noise = "mbw", 3.0, 1.1, 1.1, 0.5

        @staticmethod
        def say(*a, **k):
            pass
    one, two, fb = {"dynamics.modes": 1.0}, {"dynamics.modes": 2.0}, {"dynamics.structure": "feedback"}
    res = [{"var": one, "r": 1.0, "vals": {"fn": 400.0}, "done": None, "score": 0.5, "ev": "e", "seconds": 0.1},
           {"var": fb, "r": 9.0, "vals": {}, "done": None, "seconds": 0.1},
           {"var": two, "r": 2.0, "vals": {"fn2": 800.0}, "done": None, "seconds": 0.1}]
    cand, vals, done, var = _screened(S, "dynamics", res)
    assert isinstance(cand, Candidate) and var == one and vals == {"fn": 400.0}
    assert cand.runner_up == ({"fn2": 800.0}, two)
    assert cand.alike == []  # 2.0 against 1.0: the record chose
    res[2]["done"] = ("model", "theta", "residual")  # a joint refit already: nothing more to refit
    assert _screened(S, "dynamics", res)[0].runner_up is None
    assert _screened(S, "dynamics", res[:1])[0].runner_up is None


def test_configurations_that_screen_alike_are_kept_with_their_values():
    """Configurations within min_factor of the best — or, while the best leaves error above the noise floor,
    within what it leaves there — are handed on with the base and effect values each reached (the ladder refits
    later rungs in them: diagnose.alike); the kept one is among them."""
    class Base:
        @staticmethod
        def unpack(th):
            return {"zeta1": th[0]}

    class S:
        base, base_val, min_factor, base_model, th_base = "mbw", 3.0, 1.1, Base, (0.3,)
        noise_margin, noise = 1.1, 1.0 / 1.1  # the best (1.0) at the noise floor: nothing left to tip the choice

        @staticmethod
        def say(*a, **k):
            pass
    log, lags = {"creep.form": "log"}, {"creep.form": "lags"}
    joint = (type("M", (), {"unpack": staticmethod(lambda th: {"zeta1": 0.25, "creep.gain": th})}), 0.06, None)
    res = [{"var": log, "r": 1.05, "vals": {"creep.gain": 0.06}, "done": joint, "score": 0.5, "ev": "e",
            "seconds": 0.1},
           {"var": lags, "r": 1.0, "vals": {"creep.gain": 0.1}, "done": None, "seconds": 0.1}]
    cand, vals, done, var = _screened(S, "creep", res)
    assert var == lags
    assert cand.alike == [(lags, {"zeta1": 0.3, "creep.gain": 0.1}), (log, {"zeta1": 0.25, "creep.gain": 0.06})]
    res[0]["r"] = 1.2  # no longer within 1.1x: the record chose
    assert _screened(S, "creep", res)[0].alike == []

    class Above(S):  # the best 10x above the floor: another effect may explain 1.2² − 1.0² of it
        noise = 0.1
    assert [v for v, _ in _screened(Above, "creep", res)[0].alike] == [lags, log]
    res[0]["r"] = 1.5  # 1.5² − 1.0² exceeds all the best leaves above the floor (1.0² − 0.11²)
    assert _screened(Above, "creep", res)[0].alike == []
