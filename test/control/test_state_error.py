"""The published ``error`` is the tracking error: each measurement against the reference it was commanded for."""
import numpy as np
import pytest

from hyst_bringup.loop import default_plant

from hyst_control.controllers import ALGORITHMS, make_controller
from hyst_control.reference import parse_reference
from hyst_model.core import pea_default

DT = 5e-4


@pytest.mark.parametrize("alg", ALGORITHMS)
def test_state_error_is_y_k_minus_the_reference_for_sample_k(alg):
    plant = default_plant(1.0 / DT, seed=1)
    ref = parse_reference("sine:10")
    c = make_controller(alg, pea_default(), DT)
    y = plant.reset(0.0)
    c.reset(y, 0.0)
    rs, ys, published = [], [], []
    for k in range(400):
        r = float(ref((k + 1) * DT))       # the target of the command computed now (the sample it produces)
        u = c.step(r, y)
        published.append(c.state()["error"])
        rs.append(r)
        y = plant.step(u)
        ys.append(y)
    # after step k the newest measurement is ys[k-1], produced by the command aimed at rs[k-1]
    true = np.array(ys[:-1]) - np.array(rs[:-1])
    np.testing.assert_allclose(np.array(published[1:]), true, rtol=0, atol=1e-15)
    # and it is not the old y_k − r_{k+1}: at 10 Hz that differs by the reference's change per sample
    old = np.array(ys[:-1]) - np.array(rs[1:])
    assert np.sqrt(np.mean((old - true) ** 2)) > 1e-7
