"""read_settings: the controller node's parameters to plain settings, every check made, without ROS."""
from __future__ import annotations

import pytest

from hyst_common.profiles import PEA_LIMITS
from hyst_control.controller_settings import GAINS, MODEL_KEYS, profile_model, read_settings
from hyst_control.errors import ControlError


def _params(**over):
    m = profile_model("pea")
    d = {"profile": "pea", "algorithm": "dppc", "model.base": "mbw", "model.dt": 0.0, "rate": 1000.0,
         "dmrac.initial": "model",
         "model.effects": (), "stability.policy": "derate", "stability.notch": True, "stability.gain_margin": 2.0,
         "v_min": PEA_LIMITS.v_min, "v_max": PEA_LIMITS.v_max, "slew_max": PEA_LIMITS.slew_max,
         "v_safe": PEA_LIMITS.v_safe, "safe_ramp_rate": 100.0, "watchdog_periods": 100, "state_decimation": 10,
         "reference": ""}
    d.update({f"{a}.{n}": g.default for a, (_, spec) in GAINS.items() for n, g in spec.items()})
    d.update({f"model.{k}": float(getattr(m, k)) for k in MODEL_KEYS})
    d.update({k.replace("__", "."): v for k, v in over.items()})
    return d.__getitem__


def test_the_defaults_give_the_profile_model_and_the_configured_gains():
    s = read_settings(_params(), ())
    assert s.algorithm == "dppc" and s.rate == 1000.0 and s.model == profile_model("pea")
    assert s.gains("dppc") == s.configured("dppc") and s.effects == () and s.reference is None
    assert read_settings(_params(algorithm="pid", reference="sine:5"), ()).reference is not None


@pytest.mark.parametrize(("over", "why"), [
    ({"algorithm": "lqr"}, "algorithm must be one of"),
    ({"model__base": "bw"}, "model.base must be 'mbw'"),
    ({"model__dt": 0.0005}, "set rate:=2000"),
    ({"dmrac__initial": "cs9"}, "dmrac.initial"),
    ({"stability__policy": "hope"}, "stability.policy"),
    ({"stability__notch": "yes"}, "stability.notch"),
])
def test_a_parameter_set_the_laws_cannot_run_is_refused_with_its_reason(over, why):
    with pytest.raises(ControlError, match=why.replace(".", r"\.")):
        read_settings(_params(**over), ())


def test_a_model_period_a_clocks_error_off_the_loops_runs_and_a_rate_apart_does_not():
    """hyst fit writes the record's median period: 1.00002 ms (a 20 ppm clock) was refused at 1 kHz."""
    assert read_settings(_params(model__dt=1.00002e-3), ()).rate == 1000.0
    assert read_settings(_params(model__dt=1.000656e-3), ()).rate == 1000.0
    with pytest.raises(ControlError, match="set rate:="):
        read_settings(_params(model__dt=1.01e-3), ())


def test_a_model_identified_far_below_the_limits_reach_is_refused_as_another_actuators():
    """A GMA model fitted on −4.8…1.4 V (u_scale 0.48 V per unit) ran DPPC on the PEA's 0–150 V with a warning."""
    with pytest.raises(ControlError, match="another actuator"):
        read_settings(_params(model__u_scale=0.48), ())
    assert read_settings(_params(model__u_scale=1.5), ()).model.u_scale == 1.5  # 15 V of 150: 10×, still taken


def test_an_internal_reference_sits_on_the_stroke_of_the_profile_model():
    """sine:5 is 5–25 µm on the PEA (as documented); on the GMA (±20 µm) it was placed there too and half of it was
    out of reach: another profile's reference now sits on its model's rest stroke as the sine sits on the PEA's."""
    from hyst_common.profiles import GMA_LIMITS
    from hyst_control.reference import parse_reference

    pea = read_settings(_params(reference="sine:5"), ()).reference
    assert pea == parse_reference("sine:5")
    m = profile_model("gma")
    lo, hi = m.rest_output(GMA_LIMITS.v_min), m.rest_output(GMA_LIMITS.v_max)
    gma = dict(profile="gma", v_min=GMA_LIMITS.v_min, v_max=GMA_LIMITS.v_max, slew_max=GMA_LIMITS.slew_max,
               v_safe=GMA_LIMITS.v_safe, reference="sine:5",
               **{f"model__{k}": float(getattr(m, k)) for k in MODEL_KEYS})
    ref = read_settings(_params(**gma), ()).reference
    assert lo < -15e-6 and hi > 15e-6  # the GMA's ±20 µm
    assert lo < ref.offset - ref.amplitude and ref.offset + ref.amplitude < hi
    assert ref.offset == pytest.approx(lo + (hi - lo) * 0.5) and ref.amplitude == pytest.approx((hi - lo) / 3)
    # numbers given in the spec stay the absolute µm they say
    assert read_settings(_params(**{**gma, "reference": "sine:5:4"}), ()).reference.amplitude == pytest.approx(4e-6)
