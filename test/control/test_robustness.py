"""Every algorithm stays bounded and NaN-free with a 20 % model error and with each sim effect switched on."""
import numpy as np
import pytest

from hyst_control.dmrac import DMRACGains
from hyst_control.dppc import DPPCGains
from hyst_bringup.loop import default_plant, run_closed_loop
from hyst_control.controllers import ALGORITHMS, make_controller, mismatched
from hyst_control.pid import PIDGains
from hyst_model.core import pea_default

DT = 5e-4
#: One clearly visible strength per hyst_sim effect (hyst_sim.truth_effects).
EFFECTS = {"creep": 0.05, "asymmetry": 0.1, "dynamics": 800.0, "delay": 2, "drift": 5e-7, "saturation": 0.2,
           "noise": 50e-9, "quantization": 20e-9}


def _check(res, limit_um):
    assert res.finite
    assert res.u.min() >= 0.0 and res.u.max() <= 150.0
    assert np.max(np.abs(np.diff(res.u))) <= 1e5 * DT + 1e-9
    assert res.rmse < limit_um * 1e-6, res.summary()


@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("mismatch", [0.2, -0.2])
def test_twenty_percent_mismatch_is_bounded(algorithm, mismatch):
    c = make_controller(algorithm, mismatched(pea_default(), mismatch), DT)
    res = run_closed_loop(c, "c1", 0.5, plant=default_plant(2000.0))
    # feedback laws track within a fraction of a µm; open loop is off by the model error (several µm)
    _check(res, 6.0 if algorithm == "open_loop" else 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("effect", list(EFFECTS))
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_each_sim_effect_is_bounded_and_nan_free(algorithm, effect):
    plant = default_plant(2000.0, seed=1, **{effect: EFFECTS[effect]})
    c = make_controller(algorithm, pea_default(), DT)
    res = run_closed_loop(c, "sine:10", 0.5, plant=plant)
    if effect == "dynamics" and algorithm in ("dppc", "pid"):
        # Table 4.2's χ = 0.1 (and an aggressive PID) excite an 800 Hz resonance into a limit cycle: still
        # bounded and finite (the limiter holds it), but useless — see the robust gains test below.
        _check(res, 30.0)
        # a limit cycle, not a stalled loop (a law stuck on a rail scores 16.6 µm and passes the RMSE check):
        # the command keeps switching sample to sample (measured 22–25 V RMS steps, 45–50 V span)
        late = res.u[res.u.size // 2:]
        assert np.std(np.diff(late)) > 5.0 and np.ptp(late) > 20.0, res.summary()
        return
    _check(res, 12.0)  # bounded: never more than a stroke-fraction off, whatever the effect
    if algorithm != "open_loop" and effect not in ("delay", "dynamics", "saturation"):
        _check(res, 1.0)  # feedback keeps the slow/sensor effects below 1 µm RMSE


@pytest.mark.parametrize(("algorithm", "gains", "limit_um"), [
    ("dppc", DPPCGains(chi=0.7), 0.3), ("dmrac", DMRACGains(a_m=0.8), 0.1), ("pid", PIDGains(kp=0.0, ki=2e9), 1.5)])
def test_slower_error_dynamics_tolerate_an_800_hz_resonance(algorithm, gains, limit_um):
    plant = default_plant(2000.0, seed=1, dynamics=800.0)
    c = make_controller(algorithm, pea_default(), DT, gains=gains)
    _check(run_closed_loop(c, "sine:10", 0.5, plant=plant), limit_um)
