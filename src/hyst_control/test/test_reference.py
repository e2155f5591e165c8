"""Reference generators: documented values, analytic rates, parse errors."""
import numpy as np
import pytest

from hyst_control.errors import ReferenceError_
from hyst_control.reference import TABLE_REFERENCES, parse_reference

SPECS = list(TABLE_REFERENCES) + ["case3", "sine:7:3", "constant:12"]


@pytest.mark.parametrize("spec", SPECS)
def test_rate_is_the_derivative_and_values_stay_in_the_stroke(spec):
    ref = parse_reference(spec)
    t = np.arange(0, 4.0, 1e-5)
    r, v = ref.sample(t)
    assert np.all((r >= 0) & (r <= 30e-6))
    num = np.gradient(r, t)
    smooth = (np.abs(np.diff(r, prepend=r[0])) < 1e-7) & (np.abs(np.diff(v, prepend=v[0])) < 0.05 * np.max(np.abs(v)))
    mask = smooth & np.roll(smooth, 1) & np.roll(smooth, -1)  # away from steps and kinks
    np.testing.assert_allclose(v[mask][5:-5], num[mask][5:-5], atol=2e-3 * max(1e-6, np.max(np.abs(v))) + 1e-9)


def test_documented_values():
    assert parse_reference("step")(0.0) == pytest.approx(5e-6)
    assert parse_reference("step")(0.2) == pytest.approx(20e-6)
    assert parse_reference("step+ramp")(0.1) == pytest.approx(12.5e-6)
    assert parse_reference("ramp")(1.0) == pytest.approx(20e-6)
    s = parse_reference("sine:10")
    assert s(0.025) == pytest.approx(25e-6)
    c3 = parse_reference("case3")
    t = 0.3
    expect = 15e-6 + 2 * (3e-6 * np.sin(2 * np.pi * 3.5 * t) + 1.5e-6 * (np.cos(2 * np.pi * 1.5 * t) - 1))
    assert c3(t) == pytest.approx(expect)
    for spec in ("c1", "c2", "c3", "case3", "sine:3"):
        assert parse_reference(spec)(0.0) == pytest.approx(15e-6)


def test_c2_sweeps_frequency_continuously():
    ref = parse_reference("c2")
    t = np.arange(0, 8.0, 1e-5)
    r = ref(t)
    assert np.max(np.abs(np.diff(r))) < 2 * np.pi * 20 * 10e-6 * 1e-5 * 1.01


@pytest.mark.parametrize("bad", ["", "sine", "sine:abc", "sine:-1", "wave", "sine:1000"])
def test_bad_specs_get_a_clear_error(bad):
    with pytest.raises(ReferenceError_):
        parse_reference(bad)
