"""Controllers on the identified model: effects planned, inverted around the laws, and the error falls."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hyst_control.compensation import Compensated, effect_parameters, plan_compensation
from hyst_control.errors import ConfigError
from hyst_bringup.loop import default_plant, run_closed_loop
from hyst_control.controllers import make_controller
from hyst_model.core import pea_default

RATE = 2000.0
DT = 1.0 / RATE


def _plan(effects, **values):
    vals = {k: v for k, (v, _) in effect_parameters(DT, 15.0, 5.42e-6).items()}
    vals.update({k.replace("__", "."): v for k, v in values.items()})
    return plan_compensation(pea_default(), effects, vals, vals, DT)


def test_plan_uses_what_has_an_inverse_and_names_the_rest():
    comp = _plan(["creep", "drift", "dynamics", "hum"], creep__gain=0.01, dynamics__fn=350.0, dynamics__zeta=0.04)
    assert comp.names == ["creep", "drift", "dynamics"]
    assert set(comp.unused) == {"hum"}
    assert "user effect" in comp.unused["hum"]
    assert "compensating creep, drift, dynamics" in comp.describe() and "not compensated: hum" in comp.describe()
    # drift is estimated from the sensor: the open-loop inverse cannot use it, and says so
    assert comp.sensor_only == ["drift"]
    ol = comp.describe("open_loop")
    assert "compensating creep, dynamics" in ol and "drift: estimated from the sensor" in ol


def test_plan_refuses_missing_out_of_range_and_uninvertible_effects():
    with pytest.raises(ConfigError, match="creep.tilt"):
        plan_compensation(pea_default(), ["creep"], {"creep.gain": 0.01}, {}, DT)
    with pytest.raises(ConfigError, match="outside"):
        _plan(["creep"], creep__gain=5.0)
    with pytest.raises(ConfigError, match="cannot be inverted"):
        _plan(["creep"], creep__gain=0.29)


def test_a_resonance_without_an_inverse_is_reported_not_a_refusal_of_the_model():
    """A diagnosed mode read a sample into the hold has no stable inverse: the model is still used (creep
    compensated), the mode is named with the reason, and (the node, hyst track) the gains are checked against it."""
    from hyst_control.stability import identified_resonance

    vals = dict(creep__gain=0.01, dynamics__fn=797.0, dynamics__zeta=0.05, dynamics__part=1.0, dynamics__lag=0.5)
    comp = _plan(["creep", "dynamics"], **vals)
    assert comp.names == ["creep"] and "dynamics" in comp.unused
    assert "unit circle" in comp.unused["dynamics"] and "gains are still checked" in comp.unused["dynamics"]
    res = identified_resonance(["creep", "dynamics"], {k.replace("__", "."): v for k, v in vals.items()})
    assert res is not None and res.fn == 797.0 and res.lag == 0.5


def test_limits_set_on_the_wrapper_reach_the_law():
    from hyst_common.limits import CommandLimits

    c = make_controller("dppc", pea_default(), DT, compensation=_plan(["creep"], creep__gain=0.01))
    assert isinstance(c, Compensated)
    new = CommandLimits(10.0, 100.0, 1e5, 20.0)
    c.limits = new
    assert c.inner.limits is new and c.limits is new


def test_no_effects_leaves_the_law_unwrapped():
    c = make_controller("dppc", pea_default(), DT, compensation=_plan([]))
    assert not isinstance(c, Compensated)


def _track(alg, plant_effects, comp, ref="sine:1", seconds=1.5, record=()):
    c = make_controller(alg, pea_default(), DT, compensation=comp)
    return run_closed_loop(c, ref, seconds, plant=default_plant(RATE, seed=3, **plant_effects), settle=0.5,
                           record=record)


@pytest.mark.parametrize("alg", ["dppc", "dmrac", "open_loop"])
def test_input_delay_compensated_by_the_smith_predictor(alg):
    """A 3 ms amplifier delay on the stage: the base-model law is far off; with the identified delay it is not."""
    plant = {"delay": 6}  # samples at 2 kHz
    base = _track(alg, plant, None)
    comp = _track(alg, plant, _plan(["delay"], delay__tau=0.003, **{"delay__side": "input"}))
    assert comp.finite and comp.rmse < 30e-9, comp.rmse
    assert base.rmse > 5 * comp.rmse, (base.rmse, comp.rmse)


@pytest.mark.parametrize("alg", ["dppc", "open_loop"])
def test_creep_compensated_from_the_identified_operator(alg):
    """The stage's creep (the sim's own creep law, not the library's) against the library's creep operator."""
    plant = {"creep": 0.012}
    base = _track(alg, plant, None, ref="c1", seconds=3.0)
    comp = _track(alg, plant, _plan(["creep"], creep__gain=0.012), ref="c1", seconds=3.0)
    assert comp.rmse < base.rmse / 2, (base.rmse, comp.rmse)


@pytest.mark.parametrize("alg", ["dppc", "dmrac"])
def test_drift_removed_by_the_observer(alg):
    """A drifting sensor offset (the sim's: ramp, thermal sine and random walk): without the drift term the laws
    keep a share of the offset ((1 − δ1)·d for DPPC); with it they sit near the drift-free stage's level."""
    plant = {"drift": 2e-7}
    clean = _track(alg, {}, None, seconds=3.0)
    base = _track(alg, plant, None, seconds=3.0)
    comp = _track(alg, plant, _plan(["drift"]), seconds=3.0)
    assert comp.finite and base.finite
    assert comp.rmse < 0.5 * base.rmse, (base.rmse, comp.rmse)
    assert comp.rmse < 1.5 * clean.rmse, (clean.rmse, comp.rmse)


def test_drift_observer_is_not_fed_in_open_loop():
    """Open loop reads no sensor: its drift estimate stays 0 and its commands equal the plain inverse's."""
    plant = {"drift": 2e-7}
    plain = _track("open_loop", plant, None)
    comp = _track("open_loop", plant, _plan(["drift"]))
    assert comp.rmse == pytest.approx(plain.rmse, rel=1e-9)


def test_a_sensor_drift_is_in_the_reading_not_in_the_stage_position():
    """The sim's drift is its sensor's offset: the open loop's reading carries it while the stage goes where it
    was sent; a feedback law follows the reading, so the drift moves the stage instead."""
    plant = {"drift": 2e-7}
    clean = _track("open_loop", {}, None, seconds=3.0)
    ol = _track("open_loop", plant, None, seconds=3.0)
    fb = _track("dppc", plant, _plan(["drift"]), seconds=3.0)
    assert clean.x is not None and ol.x is not None and fb.x is not None
    assert ol.rmse > 5 * clean.rmse, (ol.rmse, clean.rmse)  # the reading drifts away
    assert ol.rmse_position < 1.5 * clean.rmse_position + 1e-9, (ol.rmse_position, clean.rmse_position)
    assert fb.rmse < 0.2 * ol.rmse and fb.rmse_position > 5 * fb.rmse, (fb.rmse, fb.rmse_position)


@pytest.mark.parametrize("alg", ["dppc", "dmrac"])
def test_a_sensor_side_drift_puts_the_stage_position_on_the_reference(alg):
    """``drift.side: sensor`` (the sensor's offset drifts, the stage does not): the feedback laws put the reading
    minus the estimated offset on the reference, so the stage's position stays on it and the reading shows the
    drift — where ``stage`` (the default) moves the stage by the drift to hold the reading. What is left on the
    position is the observer's lag behind the drift's random walk (the sim's drift: ramp, thermal sine and walk;
    measured 10 nm of 580 nm, against 1.8 nm on the drift-free stage)."""
    plant = {"drift": 2e-7}
    clean = _track(alg, {}, None, seconds=3.0)
    keys = ("error", "drift", "position_error")
    stage = _track(alg, plant, _plan(["drift"]), seconds=3.0, record=keys)
    sensor = _track(alg, plant, _plan(["drift"], **{"drift__side": "sensor"}), seconds=3.0, record=keys)
    assert sensor.finite and stage.finite and sensor.x is not None and stage.x is not None
    assert sensor.rmse_position < 0.05 * stage.rmse_position, (sensor.rmse_position, stage.rmse_position)
    assert sensor.rmse_position < 0.05 * sensor.rmse, (sensor.rmse_position, sensor.rmse)  # the reading drifts
    assert stage.rmse < 1.5 * clean.rmse, (stage.rmse, clean.rmse)  # the default keeps the reading on it
    # /controller/state names the estimate and, for a drifting sensor, the position's error
    st, ss = stage.states, sensor.states
    assert np.all(np.isnan(st["position_error"])) and not np.any(np.isnan(ss["position_error"]))
    late = slice(-1000, None)
    assert abs(ss["drift"][-1]) > 100e-9 and abs(st["drift"][-1]) > 100e-9
    assert np.sqrt(np.mean(np.square(ss["position_error"][late]))) < 0.1 * np.sqrt(
        np.mean(np.square(ss["error"][late])))


def test_a_sensor_side_drift_needs_no_reading_in_open_loop_and_a_bad_side_is_refused():
    comp = _plan(["drift"], **{"drift__side": "sensor"})
    assert comp.sensor_only == [] and comp.describe("open_loop") == "compensating drift"
    assert _plan(["drift"]).sensor_only == ["drift"]
    with pytest.raises(ConfigError, match="drift.side must be one of stage, sensor"):
        _plan(["drift"], **{"drift__side": "amplifier"})


def test_declared_configuration_defaults_mean_what_a_file_without_the_key_means():
    """A node declares every effect key with a default; a params file that lacks one must read as the effect does
    without it (a quadratic asymmetry file was read as a kink of zero slope: the asymmetry went uncompensated)."""
    from hyst_model.effects import EFFECTS

    declared = effect_parameters(DT, 15.0, 5.42e-6)
    base = {"dt": DT, "u_scale": 15.0, "y_scale": 5.42e-6}
    for name, cls in EFFECTS.items():
        for k, v in cls(base).config().items():
            assert declared[f"{name}.{k}"][0] == v, (name, k)
    assert declared["asymmetry.form"][0] == "quadratic"
    assert declared["creep.form"][0] == "log" and "creep.tau1" in declared  # both forms' parameters declared


def test_saturation_respected_as_a_limit():
    """A reference beyond the identified stroke limit is held at the limit: no wind-up, counted."""
    top = 20e-6
    comp = _plan(["saturation"], saturation__top=top, saturation__width=2e-6, saturation__bottom=-1e-3)
    c = make_controller("dppc", pea_default(), DT, compensation=comp)
    r = run_closed_loop(c, "sine:1:30", 1.0, plant=default_plant(RATE, seed=1), settle=0.2, record=("limited",))
    assert r.finite
    assert r.states["limited"][-1] > 0
    # the stage (no saturation in this plant) is driven to the model's reachable limit, not beyond
    assert r.y.max() < comp.target(top, 0.0) + 50e-9
    assert math.isfinite(r.u.max()) and r.u.max() <= 150.0


def test_effects_get_their_parameters_as_an_array(monkeypatch):
    """Effect.online takes θ as an array: a user effect's array arithmetic must work on it (a list repeated)."""
    from hyst_model.effects import EFFECTS, Effect
    from hyst_model.model import Param

    seen = []

    class Doubled(Effect):
        name = "doubled_test"
        kind = "output"

        def params(self):
            return (Param("gain", 0.0, -1.0, 1.0),)

        def online(self, theta, base=None):
            seen.append(theta * 2)
            return None

    monkeypatch.setitem(EFFECTS, "doubled_test", Doubled)
    comp = plan_compensation(pea_default(), ["doubled_test"], {"doubled_test.gain": 0.25}, {}, DT)
    assert list(seen[0]) == [0.5]
    assert "doubled_test" in comp.unused


class _ModelPlant:
    """The extended model itself as the stage (no noise): each step re-simulates the whole input history."""

    def __init__(self, effects, values, config):
        import numpy as np

        from hyst_model.spec import build_model

        m = pea_default()
        cfg = {**config, "dt": DT, "u_scale": m.u_scale, "y_scale": m.y_scale, "offset": m.offset}
        self._model = build_model("mbw", list(effects), cfg)
        vals = {**{k: float(getattr(m, k)) for k in ("zeta1", "zeta2", "psi1", "psi2", "alpha1", "alpha2",
                                                     "delta1", "delta2", "offset")}, **values}
        self._theta = np.array([vals[p.name] for p in self._model.params()])
        self._np = np
        self.dt = DT

    def _out(self) -> float:
        u = self._np.array(self._u)
        return float(self._model.simulate(self._theta, self._np.arange(u.size) * DT, u)[-1])

    def reset(self, u0: float) -> float:
        self._u = [u0] * 400
        return self._out()

    def step(self, u: float) -> float:
        self._u.append(u)
        return self._out()


_EXACT_CASES = {
    "creep": {"creep.gain": 0.03, "creep.tilt": 0.1},
    "asymmetry": {"asymmetry.a_y": -0.003, "asymmetry.u_c": 75.0, "asymmetry.y_c": 15e-6},
    "asymmetry-kink": {"asymmetry.form": "kink", "asymmetry.slope": 0.1, "asymmetry.level": 18e-6,
                       "asymmetry.y_lo": 0.0, "asymmetry.y_hi": 30e-6},
    "delay": {"delay.tau": 0.0015, "delay.side": "input"},
    "delay-output": {"delay.tau": 0.001, "delay.side": "output"},
    "dynamics": {"dynamics.fn": 350.0, "dynamics.zeta": 0.05},
    # read a whole sample into the hold: the lag-0 mode one sample later, inverted as such
    "dynamics-lag1": {"dynamics.fn": 797.0, "dynamics.zeta": 0.05, "dynamics.lag": 1.0},
    # a resonance or a delay identified outside creep: applied directly on the base (they commute; 300 nm off)
    "creep+dynamics": {"creep.gain": 0.03, "creep.tilt": 0.1, "dynamics.fn": 350.0, "dynamics.zeta": 0.05},
    # two predictors on the base (delay and mode): predicted as one chain, not each against the undelayed base
    "delay+dynamics": {"delay.tau": 0.001, "delay.side": "input", "dynamics.fn": 350.0, "dynamics.zeta": 0.05},
    "dynamics+delay-output": {"delay.tau": 0.001, "delay.side": "output", "dynamics.fn": 350.0,
                              "dynamics.zeta": 0.05},
    # creep outside a delay: its target reads the lags as they will be when the previewed sample arrives
    "delay+creep": {"delay.tau": 0.0015, "delay.side": "input", "creep.gain": 0.03, "creep.tilt": 0.1},
    # a mode outside a bent loop: its predictor and its inverse's state run on the bent prediction
    "asymmetry+dynamics": {"asymmetry.a_y": -0.003, "asymmetry.u_c": 75.0, "asymmetry.y_c": 15e-6,
                           "dynamics.fn": 350.0, "dynamics.zeta": 0.05},
    # creep as two lags with free time constants (creep.form: lags), alone and outside a delay
    "creep-lags": {"creep.form": "lags", "creep.gain": 0.05, "creep.tau1": 0.05, "creep.tau2": 0.8,
                   "creep.share": 0.6},
    "delay+creep-lags": {"delay.tau": 0.0015, "delay.side": "input", "creep.form": "lags", "creep.gain": 0.05,
                         "creep.tau1": 0.05, "creep.tau2": 0.8, "creep.share": 0.6},
    # an inner drift (here at its zero offset) ends the feedback laws' chain before the mode: the open loop still
    # predicts through every effect (forwarding the mode and also measuring it was 228 nm off at 30 Hz)
    "drift+dynamics+creep": {"dynamics.fn": 350.0, "dynamics.zeta": 0.05, "creep.gain": 0.03, "creep.tilt": 0.1},
    # ... and the feedback laws' chain too: the predictors move inward past the drift, which predicts with its
    # offset estimate (an inner drift broke their chain: DPPC unstable on its own model, DMRAC 246 nm off)
    "drift+delay+dynamics": {"delay.tau": 0.001, "delay.side": "input", "dynamics.fn": 350.0,
                             "dynamics.zeta": 0.05},
    "drift+creep+delay": {"delay.tau": 0.0015, "delay.side": "input", "creep.gain": 0.03, "creep.tilt": 0.1},
    "creep+asymmetry": {"creep.gain": 0.03, "creep.tilt": 0.1,
                        "asymmetry.a_y": -0.003, "asymmetry.u_c": 75.0, "asymmetry.y_c": 15e-6},
}


@pytest.mark.parametrize("case", sorted(_EXACT_CASES))
@pytest.mark.parametrize("freq", [10.0, 30.0])
@pytest.mark.parametrize("alg", ["open_loop", "dppc"])
def test_open_loop_inverts_its_own_extended_model_exactly(case, freq, alg):
    """On a stage that is exactly the identified model, the open-loop inverse with the effects compensated puts
    the output on the reference at any frequency: every per-sample inverse and its timing is exact. (The effects'
    states followed the aim of the sample before: creep was 8 nm off at 10 Hz, in phase with the reference's rate.)

    The open loop is exact from the start: its effect states follow the model's own prediction for the commands
    applied (the start's faded bump included), not the aim it is handed — with the aim, the model's slow creep
    lags kept the start's course as an offset that decayed over seconds (16.5 nm with creep and a 317 Hz mode on
    a 1 Hz sine). DPPC reads the stage, whose creep remembers the start: its slow offset is removed with a
    quadratic trend. Not tested, because approximate by construction: asymmetry's input term a_u (inverted with
    the previous command standing in for the one being computed: exact only while the input is held); a
    fractional output delay (the model interpolates between samples, which no causal inverse undoes: 4.6 nm on a
    30 Hz, 6 µm sine at 2 kHz)."""
    import numpy as np

    effects = case.split("-")[0].split("+")
    vals = {k: v for k, (v, _) in effect_parameters(DT, 15.0, 5.42e-6).items() if k.split(".")[0] in effects}
    vals.update(_EXACT_CASES[case])
    comp = plan_compensation(pea_default(), effects, vals, vals, DT)
    assert comp.names == effects  # reported in the file's order, whatever order they are applied in
    c = make_controller(alg, pea_default(), DT, compensation=comp)
    plant = _ModelPlant(effects, {k: v for k, v in vals.items() if not isinstance(v, str)}, vals)
    r = run_closed_loop(c, f"sine:{freq:g}:6", 0.25, plant=plant, settle=0.5)  # 9-21 µm: never clipped
    assert r.finite and np.all((r.u > 0.0) & (r.u < 150.0))
    e = r.y - r.r
    if alg != "open_loop":
        e = e - np.polyval(np.polyfit(r.t, e, 2), r.t)
    assert np.sqrt(np.mean(e[1:] ** 2)) < 1e-10, np.sqrt(np.mean(e[1:] ** 2))  # 0.1 nm; the stale aim: 8 nm


def test_open_loop_creep_memory_follows_the_applied_start():
    """The start fades the first command's bump out; the stage's slow creep lags remember that course. Open
    loop's effect states follow the model driven by the applied command (the compensation's prediction through
    every effect), not the aim: the start leaves no offset (11 nm when they followed the aim, 1.8 nm when they
    followed the aim moved by :attr:`OpenLoop.applied_shift`)."""
    import numpy as np

    vals = {k: v for k, (v, _) in effect_parameters(DT, 15.0, 5.42e-6).items() if k.startswith("creep.")}
    vals.update(_EXACT_CASES["creep"])
    comp = plan_compensation(pea_default(), ["creep"], vals, vals, DT)
    c = make_controller("open_loop", pea_default(), DT, compensation=comp)
    plant = _ModelPlant(["creep"], vals, vals)
    r = run_closed_loop(c, "sine:10:6", 0.25, plant=plant, settle=0.5)
    assert r.finite
    assert abs(float(np.mean(r.y - r.r))) < 1e-10, float(np.mean(r.y - r.r))


class _Disturbed:
    """A stage plus a slow output disturbance the model does not know: an offset that drifts (m, by step)."""

    def __init__(self, plant, offset: float, rate: float):
        self._p, self._d0, self._rate, self._k = plant, offset, rate, 0
        self.dt = plant.dt

    def _d(self) -> float:
        return self._d0 + self._rate * self._k * self.dt

    def reset(self, u0: float) -> float:
        self._k = 0
        return self._p.reset(u0) + self._d()

    def step(self, u: float) -> float:
        self._k += 1
        return self._p.step(u) + self._d()


@pytest.mark.parametrize("alg", ["dppc", "dmrac"])
@pytest.mark.parametrize("case", ["dynamics", "delay+dynamics", "creep", "delay+creep", "asymmetry+dynamics",
                                  "creep+dynamics", "delay"])
def test_a_disturbance_the_model_does_not_know_is_rejected_through_the_compensation(alg, case):
    """A drifting offset on a stage whose effects the compensation inverts: the feedback must remove it. The mode
    inverse's state once ran on the model's prediction alone, so it undid every correction the law made against
    the offset (the law saw no error, the stage read (1 − Γ0)·d off: 8-11x the drift-free level on generated
    stage 1009, drift + a 391 Hz mode)."""
    import numpy as np

    effects = case.split("+")
    vals = {k: v for k, (v, _) in effect_parameters(DT, 15.0, 5.42e-6).items() if k.split(".")[0] in effects}
    vals.update(_EXACT_CASES[case])
    comp = plan_compensation(pea_default(), effects, vals, vals, DT)
    c = make_controller(alg, pea_default(), DT, compensation=comp)
    model = _ModelPlant(effects, {k: v for k, v in vals.items() if not isinstance(v, str)}, vals)
    d_end = 40e-9 + 200e-9 * 0.75  # the offset at the end: 190 nm
    r = run_closed_loop(c, "sine:10:6", 0.75, plant=_Disturbed(model, 40e-9, 200e-9), settle=0.5)
    assert r.finite
    e = (r.y - r.r)[r.t > 0.25]  # after the loop has met the offset
    # a 200 nm/s ramp is followed with the observer's lag (0.05 s: 10 nm), not left standing at most of its size
    assert np.sqrt(np.mean(e ** 2)) < 0.1 * d_end, (np.sqrt(np.mean(e ** 2)), d_end)


def test_a_params_file_with_creep_as_two_lags_is_compensated_with_its_own_lags(tmp_path):
    """The file diagnose writes for the lags form (creep.form, tau1, tau2, share, tau_max) reaches the controllers
    as that operator: the compensation inverts two lags with the file's time constants, not the log law."""
    import numpy as np

    from hyst_control.compensation import from_params
    from hyst_model.effects import compose
    from hyst_model.io import read_params, spec_from_model, write_params
    from hyst_model.model import MBWModel

    m = compose(MBWModel(u_scale=15.0, y_scale=5.42e-6), ["creep"],
                {"dt": DT, "creep.form": "lags", "creep.tau_max": 4.0})
    th = m.theta0.copy()
    th[:8] = pea_default().vector
    for k, v in {"creep.gain": 0.06, "creep.tau1": 0.05, "creep.tau2": 1.5, "creep.share": 0.3}.items():
        th[m.names.index(k)] = v
    spec = read_params(write_params(tmp_path / "p.yaml", spec_from_model(m, th, dt=DT)))
    _, comp = from_params(spec, DT)
    assert comp.names == ["creep"]
    inv = comp.used[0]
    np.testing.assert_allclose(inv._a, np.exp(-DT / np.array([0.05, 1.5])))
    np.testing.assert_allclose(inv._wa / inv._a, [0.3, 0.7])
