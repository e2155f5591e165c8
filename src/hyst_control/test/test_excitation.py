"""Excitation generator: inside the range and slew, starts/ends at rest, seeded, every part present."""
import numpy as np
import pytest

from hyst_control.errors import ConfigError
from hyst_control.excitation import DEFAULT_PARTS, PARTS, ExcitationSpec, build_excitation, from_samples


@pytest.mark.parametrize("kw", [dict(), dict(v_min=-5.0, v_max=5.0, slew_max=1e4),
                                dict(v_min=10.0, v_max=90.0, slew_max=2e4, dt=1e-3, seed=7)])
def test_range_slew_rest_and_parts(kw):
    spec = ExcitationSpec(**kw)
    ex = build_excitation(spec)
    assert np.all(ex.u >= spec.v_min) and np.all(ex.u <= spec.v_max)
    assert np.max(np.abs(np.diff(ex.u))) <= spec.slew_max * spec.dt * (1 + 1e-12)
    assert ex.u[0] == spec.rest and ex.u[-1] == pytest.approx(spec.rest)
    assert [s[0] for s in ex.segments] == list(DEFAULT_PARTS)
    assert np.allclose(np.diff(ex.t), spec.dt)
    # sines reach the largest band (within the slew limit's corner rounding)
    name, a, b = ex.segments[1]
    span = spec.v_max - spec.v_min
    assert np.ptp(ex.u[a:b]) > 0.9 * max(spec.amplitudes) * (span if spec.rest == spec.v_min else span / 2) * 0.99


def test_rest_is_centre_for_bipolar_and_bottom_for_unipolar():
    assert ExcitationSpec(v_min=-5.0, v_max=5.0).rest == 0.0
    assert ExcitationSpec(v_min=0.0, v_max=150.0).rest == 0.0
    assert ExcitationSpec(v_min=20.0, v_max=150.0).rest == 20.0


def test_seeded():
    a = build_excitation(ExcitationSpec(seed=3)).u
    assert np.array_equal(a, build_excitation(ExcitationSpec(seed=3)).u)
    assert not np.array_equal(a, build_excitation(ExcitationSpec(seed=4)).u)


def test_sweep_covers_its_band():
    spec = ExcitationSpec(parts=("sweep",), f_lo=1.0, f_hi=40.0, seconds=4.0, dt=1e-3, hold=0.0)
    ex = build_excitation(spec)
    _, a, b = ex.segments[0]
    x = ex.u[a:b] - ex.u[a:b].mean()
    f = np.fft.rfftfreq(len(x), spec.dt)
    p = np.abs(np.fft.rfft(x)) ** 2
    # the fade from and back to rest adds a little power below f_lo, nothing above the band
    assert p[(f >= 1.0) & (f <= 40.0)].sum() > 0.8 * p.sum()
    assert p[f > 45.0].sum() < 1e-3 * p.sum()


@pytest.mark.parametrize("kw", [dict(v_min=5.0, v_max=5.0), dict(parts=("chirp",)), dict(parts=()),
                                dict(amplitudes=(1.5,)), dict(f_hi=2000.0, dt=1e-3), dict(dt=0.0),
                                dict(slew_max=0.0), dict(periods=0)])
def test_bad_specs_refused(kw):
    with pytest.raises(ConfigError):
        ExcitationSpec(**kw)


def test_noise_is_seeded_band_limited_and_inside_the_limits():
    spec = ExcitationSpec(parts=("noise",), f_lo=5.0, f_hi=80.0, seconds=4.0, dt=5e-4, hold=0.0, slew_max=1e5,
                          seed=11)
    ex = build_excitation(spec)
    assert [s[0] for s in ex.segments] == ["noise"]
    assert np.all(ex.u >= spec.v_min) and np.all(ex.u <= spec.v_max)
    assert np.max(np.abs(np.diff(ex.u))) <= spec.slew_max * spec.dt * (1 + 1e-12)
    _, a, b = ex.segments[0]
    m = int(0.4 / spec.dt)  # between the fades from and back to rest (a slow ramp to the band's centre)
    x = ex.u[a + m:b - m] - ex.u[a + m:b - m].mean()
    f = np.fft.rfftfreq(len(x), spec.dt)
    p = np.abs(np.fft.rfft(x)) ** 2
    assert p[(f >= 4.0) & (f <= 81.0)].sum() > 0.97 * p.sum()
    assert p[f > 100.0].sum() < 1e-3 * p.sum()
    assert np.ptp(x) > 0.5 * 0.95 * 150.0  # peak-normalised into the largest band: not a whisper
    assert np.array_equal(ex.u, build_excitation(spec).u)
    assert not np.array_equal(ex.u, build_excitation(ExcitationSpec(**{**spec.__dict__, "seed": 12})).u)


def test_default_parts_are_the_five_measured_ones_and_noise_is_asked_for():
    assert "noise" in PARTS and "noise" not in ExcitationSpec().parts
    assert [s[0] for s in build_excitation(ExcitationSpec()).segments] == list(DEFAULT_PARTS)


def test_noise_band_without_a_bin_is_refused():
    with pytest.raises(ConfigError, match="no frequency"):
        build_excitation(ExcitationSpec(parts=("noise",), f_lo=1.0, f_hi=1.1, seconds=0.01, dt=1e-3))


def test_samples_of_a_generated_excitation_are_accepted_unchanged():
    spec = ExcitationSpec(v_min=-5.0, v_max=5.0, slew_max=1e4, dt=1e-3, parts=("steps", "noise"), seed=2)
    ex = build_excitation(spec)
    got = from_samples(ex.t + 3.0, ex.u, spec)  # a file's clock need not start at 0
    assert np.array_equal(got.u, ex.u) and np.allclose(got.t, ex.t) and got.segments == (("file", 0, ex.u.size),)


@pytest.mark.parametrize("change,match", [
    (lambda t, u: (t * 2, u), "sampled every"),
    (lambda t, u: (np.r_[t[:10], t[10:] + 0.5e-3], u), "between rows 9 and 10"),
    (lambda t, u: (t, np.where(np.arange(u.size) == 50, 151.0, u)), "outside 0..150 V"),
    (lambda t, u: (t, np.where(np.arange(u.size) == 50, u[49] + 80.0, u)), "faster than the slew"),
    (lambda t, u: (t[:400], u[:400]), "ends at"),   # cut while holding the first level
    (lambda t, u: (t[400:], u[400:]), "starts at"),
    (lambda t, u: (t[:1], u[:1]), "at least two"),
    (lambda t, u: (t, np.where(np.arange(u.size) == 5, np.nan, u)), "NaN"),
])
def test_samples_breaking_a_limit_are_refused_with_the_reason(change, match):
    spec = ExcitationSpec(slew_max=1e4, dt=1e-3, parts=("steps",), n_steps=3, seed=1)  # 10 V a sample
    ex = build_excitation(spec)
    assert ex.u[400] > 10.0  # the first step level (seed 1), held from sample 250 + 5
    t, u = change(ex.t.copy(), ex.u.copy())
    with pytest.raises(ConfigError, match=match):
        from_samples(t, u, spec)


@pytest.mark.parametrize("parts", [("steps",), ("sines", "triangles"), ("multisine", "sweep", "noise")])
@pytest.mark.parametrize("dt", [1e-3, 1 / 1234.5])
def test_the_length_is_known_before_building(parts, dt):
    spec = ExcitationSpec(parts=parts, amplitudes=(0.2, 0.5, 1.0), dt=dt, hold=0.37, step_rise=0.013, periods=2,
                          frequency=3.3, n_steps=5, seconds=1.1, f_lo=1.0, f_hi=50.0)
    assert build_excitation(spec).u.size == spec.samples


@pytest.mark.parametrize("kw", [{"hold": 1e6}, {"seconds": 1e7}, {"periods": 10**9}, {"n_steps": 10**9},
                                {"step_rise": 1e9}, {"frequency": 1e-9}])
def test_an_excitation_beyond_an_hour_is_refused_before_any_array(kw):
    with pytest.raises(ConfigError, match="at most 3600 s"):
        ExcitationSpec(**kw)
