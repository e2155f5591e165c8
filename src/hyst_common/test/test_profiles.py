"""The amplifier-range checks every node shares (hyst_common.profiles): one refusal wording for profile custom."""
import math

import pytest

from hyst_common.errors import ConfigError
from hyst_common.profiles import CUSTOM_V_MAX, check_range, custom_range


@pytest.mark.parametrize("lo, hi", [(0.0, 0.0), (5.0, -5.0), (-math.inf, 10.0), (math.nan, 10.0),
                                    (-2 * CUSTOM_V_MAX, 10.0)])
def test_a_custom_range_that_no_amplifier_has_is_refused_in_the_one_wording(lo, hi):
    with pytest.raises(ConfigError, match="profile custom needs v_min and v_max, the amplifier's range"):
        custom_range(lo, hi)
    with pytest.raises(ConfigError, match="profile custom needs v_min and v_max, the amplifier's range"):
        check_range("custom", lo, hi)


def test_a_custom_range_gives_its_limits_resting_at_zero_where_the_range_holds_it():
    lim = custom_range(-10.0, 10.0)
    assert (lim.v_min, lim.v_max, lim.v_safe) == (-10.0, 10.0, 0.0)
    assert custom_range(20.0, 120.0, slew_max=5e4).v_safe == 20.0  # the end nearer 0 V
    check_range("custom", -10.0, 10.0)  # accepted: no exception


def test_the_hardware_profiles_keep_their_own_range():
    check_range("pea", 0.0, 150.0)
    with pytest.raises(ConfigError, match="for profile pea"):
        check_range("pea", -1.0, 150.0)
