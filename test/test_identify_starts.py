"""The base fit and the delay search on generated stages where they used to fail (issue #10).

Fixed seeds of the generator (hyst_sim.generator), not the repo's own bags: MBW records without any effect
whose equation-error starts all led to a wrong basin (5-25x the noise floor), and sub-sample output and input
delays on steps that the base imitated with its δ terms (named ``dynamics`` before).
"""
import numpy as np
import pytest

from hyst_model.diagnose.diagnose import SPLIT, _scales, default_fitter, diagnose, validation_mask
from hyst_model.spec import build_model
from hyst_sim.generator import generate_case


@pytest.mark.parametrize("seed", [100033, 100118, 100178])
def test_base_fit_reaches_the_noise_floor_on_mbw_truths(seed):
    c = generate_case(seed, "none")
    cfg = dict(_scales(c.u, c.y), dt=float(c.t[1] - c.t[0]))
    m = build_model("mbw", (), cfg)
    th = default_fitter(m, c.t, c.u, c.y, None)
    val = validation_mask(c.t.size)
    e = (c.y - m.simulate(th, c.t, c.u))[val]
    assert np.sqrt(np.mean(e * e)) < 1.3 * c.noise, f"split {SPLIT}"


@pytest.mark.slow
@pytest.mark.parametrize("seed,kind", [(100004, "single_small"), (100029, "single_small"),
                                       (100039, "single_large"), (100048, "single_large")])
def test_sub_sample_delays_on_steps_are_named_delay(seed, kind):
    c = generate_case(seed, kind)
    assert c.expected == ("delay",)
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "delay", d.explanation
