"""Command/slew limits: properties over arbitrary inputs including NaN and ±inf."""
import math

import pytest
from hypothesis import given, settings, strategies as st

from hyst_control.errors import ConfigError
from hyst_control.limits import CommandLimits

LIM = CommandLimits(0.0, 150.0, 1e5, 10.0)
anyfloat = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=400, deadline=None)
@given(u=anyfloat, u_prev=st.one_of(st.floats(-1e3, 1e3), st.just(math.nan)),
       dt=st.floats(1e-5, 1e-2))
def test_output_finite_in_range_and_slew_bounded(u, u_prev, dt):
    out = LIM.apply(u, u_prev, dt)
    assert math.isfinite(out)
    assert LIM.v_min <= out <= LIM.v_max
    if LIM.v_min <= u_prev <= LIM.v_max:
        assert abs(out - u_prev) <= LIM.slew_max * dt * (1 + 1e-12)
    if math.isnan(u):
        expected = LIM.v_safe if math.isnan(u_prev) else min(max(u_prev, 0.0), 150.0)
        assert out == pytest.approx(expected, abs=LIM.slew_max * dt + 1e-12)


@settings(max_examples=200, deadline=None)
@given(u=st.floats(0.0, 150.0), u_prev=st.floats(0.0, 150.0))
def test_inside_limits_passes_unchanged(u, u_prev):
    dt = 1e-3
    out = LIM.apply(u, u_prev, dt)
    if abs(u - u_prev) <= LIM.slew_max * dt:
        assert out == u
    else:
        assert abs(out - u_prev) == pytest.approx(LIM.slew_max * dt)


def test_infinities_saturate():
    lim = CommandLimits(-5, 5)
    assert lim.apply(math.inf, 0.0, 1e-3) == 5
    assert lim.apply(-math.inf, 0.0, 1e-3) == -5


@pytest.mark.parametrize("kw", [dict(v_min=1, v_max=0), dict(v_safe=200), dict(slew_max=0),
                                dict(v_min=math.nan), dict(slew_max=math.nan)])
def test_bad_limits_rejected_with_reason(kw):
    with pytest.raises(ConfigError):
        CommandLimits(**kw)
