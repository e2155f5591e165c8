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


@pytest.mark.parametrize("bad", ["", "sine", "sine:abc", "sine:-1", "wave", "sine:1000",
                                 "sine:10:5:99", "c1:3:4", "constant:1:2"])  # extra numbers were dropped
def test_bad_specs_get_a_clear_error(bad):
    with pytest.raises(ReferenceError_):
        parse_reference(bad)


@pytest.mark.parametrize("spec", ["step", "ramp", "step+ramp", "sine:10", "c1", "c2", "c3", "case3", "constant"])
def test_a_reference_on_another_stroke_sits_on_the_same_fractions_of_it(spec):
    """``stroke=(lo, hi)``: the same shape on the same fractions of a ±20 µm stroke as of the PEA's 30 µm."""
    from hyst_control.reference import PEA_STROKE

    t = np.linspace(0.0, 4.0, 8001)
    pea = parse_reference(spec)(t)
    assert np.array_equal(parse_reference(spec, stroke=PEA_STROKE)(t), pea)   # the PEA stroke changes nothing
    lo, hi = -20e-6, 20e-6
    other = parse_reference(spec, stroke=(lo, hi))(t)
    np.testing.assert_allclose((other - lo) / (hi - lo), pea / 30e-6, atol=1e-12)


def test_numbers_in_a_spec_stay_absolute_on_another_stroke_and_a_bad_stroke_is_refused():
    r = parse_reference("sine:5:2", stroke=(-20e-6, 20e-6))
    assert r.amplitude == pytest.approx(2e-6) and r.offset == pytest.approx(0.0)
    assert parse_reference("constant:3", stroke=(-20e-6, 20e-6)).offset == pytest.approx(3e-6)
    for bad in ((1e-6, 1e-6), (float("nan"), 1e-6)):
        with pytest.raises(ReferenceError_, match="stroke"):
            parse_reference("sine:5", stroke=bad)
