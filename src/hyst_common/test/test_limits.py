"""Command/slew limits: properties over arbitrary inputs including NaN and ±inf."""
import math

import pytest
from hypothesis import given, settings, strategies as st

from hyst_common.errors import ConfigError
from hyst_common.limits import CommandLimits, limit_step

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


# The one core (limit_step) against the two clippers it replaced, kept here verbatim as references: the
# controller's CommandLimits.apply and the sim's clip_kernel (hyst_sim.profiles before issue #12).
def _old_apply(lim, u, u_prev, dt):
    have_prev = u_prev == u_prev
    if u != u:
        u = u_prev if have_prev else lim.v_safe
    lo, hi = lim.v_min, lim.v_max
    if have_prev and lim.slew_max != math.inf:
        step = lim.slew_max * dt
        lo = max(lo, u_prev - step)
        hi = min(hi, u_prev + step)
        if lo > hi:
            lo, hi = (lim.v_min, min(lim.v_max, lim.v_min + step)) if u_prev < lim.v_min else \
                (max(lim.v_min, lim.v_max - step), lim.v_max)
    return min(max(u, lo), hi)


def _old_clip(v, v_min, v_max, v_prev, max_step):
    flags = 0
    if not math.isfinite(v):
        v, flags = v_prev, 4
    else:
        if v < v_min:
            v, flags = v_min, flags | 1
        elif v > v_max:
            v, flags = v_max, flags | 1
        dv = v - v_prev
        if dv > max_step:
            v, flags = v_prev + max_step, flags | 2
        elif dv < -max_step:
            v, flags = v_prev - max_step, flags | 2
    if v < v_min:
        v, flags = v_min, flags | 1
    elif v > v_max:
        v, flags = v_max, flags | 1
    return v, flags


grid = st.integers(-400, 400).map(lambda k: k / 2.0)  # exact binary fractions: no last-bit rounding differences


@settings(max_examples=600, deadline=None)
@given(u=st.one_of(grid, st.sampled_from([math.nan, math.inf, -math.inf])),
       u_prev=st.one_of(grid, st.just(math.nan)), slew=st.sampled_from([1e3, 1e4, 1e5, math.inf]),
       dt=st.sampled_from([1e-3, 5e-4, 0.0]))
def test_controller_limits_unchanged(u, u_prev, slew, dt):
    lim = CommandLimits(-5.0, 150.0, slew, 0.0)
    assert lim.apply(u, u_prev, dt) == _old_apply(lim, u, u_prev, dt)


@settings(max_examples=600, deadline=None)
@given(v=st.one_of(grid, st.sampled_from([math.nan, math.inf, -math.inf])), v_prev=grid,
       step=st.sampled_from([0.0, 0.5, 3.0, 20.0, math.inf]), lo=st.sampled_from([-5.0, 0.0, 10.0]))
def test_sim_clip_unchanged(v, v_prev, step, lo):
    held = math.nan if not math.isfinite(v) else v  # the sim's wrapper: any non-finite command is held
    assert limit_step(held, lo, 150.0, v_prev, step) == _old_clip(v, lo, 150.0, v_prev, step)


def test_integer_grid_stays_integer():
    assert limit_step(1000, 0, 150_000_000, 10, 7) == (17, 2)
    assert limit_step(-3, 0, 150, 2, 100) == (0, 1)
