"""Registries as data: every controller, protocol and fit method is built from its one registry line."""
import dataclasses
import math

from hyst_common.params import table
from hyst_control.controllers import ALGORITHMS, CONTROLLERS, gain_table, make_controller
from hyst_model.core import pea_default


def test_every_controller_builds_by_name_with_its_gains():
    for name, law in CONTROLLERS.items():
        c = make_controller(name, pea_default(), 5e-4)
        assert isinstance(c, law.cls) and c.name == name
        if law.gains is not None:
            assert c.gains == law.gains()
    assert ALGORITHMS == tuple(CONTROLLERS)


def test_gain_table_comes_from_the_dataclasses_and_every_default_lies_in_its_range():
    gt = gain_table()
    assert set(gt) == {n for n, law in CONTROLLERS.items() if law.gains is not None}
    for name, (cls, spec) in gt.items():
        assert spec == table(cls) and list(spec) == [f.name for f in dataclasses.fields(cls)]
        for g in spec.values():
            assert g.description
            if g.lo is not None:
                assert math.isfinite(g.lo) and g.lo <= g.default <= g.hi


def test_protocols_and_fit_methods_are_registries_too():
    from hyst_driver.adapter import PROTOCOLS, make_adapter
    from hyst_model.identify import Estimator
    from hyst_model.identify.methods import METHODS, estimator_class

    for name in PROTOCOLS:
        assert make_adapter(name).name == name
    for name in METHODS:
        assert issubclass(estimator_class(name), Estimator)
