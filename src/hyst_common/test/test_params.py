"""Parameters described on their dataclass (hyst_common.params): one table from the fields' metadata."""
from dataclasses import dataclass

import pytest

from hyst_common.params import Spec, param, table


@dataclass(frozen=True)
class _Gains:
    k: float = param(0.5, 0.0, 1.0, "a gain (1)")
    on: bool = param(True, doc="switch")


def test_table_reads_default_range_and_description_in_field_order():
    assert table(_Gains) == {"k": Spec(0.5, 0.0, 1.0, "a gain (1)"), "on": Spec(True, None, None, "switch")}
    assert _Gains().k == 0.5 and _Gains(k=0.2).k == 0.2


def test_an_undescribed_field_is_refused():
    @dataclass
    class Bare:
        k: float = 1.0

    with pytest.raises(TypeError, match="Bare.k"):
        table(Bare)
