"""Excitation generator: inside the range and slew, starts/ends at rest, seeded, every part present."""
import numpy as np
import pytest

from hyst_control.errors import ConfigError
from hyst_control.excitation import PARTS, ExcitationSpec, build_excitation


@pytest.mark.parametrize("kw", [dict(), dict(v_min=-5.0, v_max=5.0, slew_max=1e4),
                                dict(v_min=10.0, v_max=90.0, slew_max=2e4, dt=1e-3, seed=7)])
def test_range_slew_rest_and_parts(kw):
    spec = ExcitationSpec(**kw)
    ex = build_excitation(spec)
    assert np.all(ex.u >= spec.v_min) and np.all(ex.u <= spec.v_max)
    assert np.max(np.abs(np.diff(ex.u))) <= spec.slew_max * spec.dt * (1 + 1e-12)
    assert ex.u[0] == spec.rest and ex.u[-1] == pytest.approx(spec.rest)
    assert [s[0] for s in ex.segments] == list(PARTS)
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
