"""The compiled time shift equals ``np.interp`` bit for bit (so the delay effect's answers did not move with it)."""
import numpy as np
import pytest

from hyst_model.effects.delay import Delay
from hyst_model.effects.sensitivity import push_through
from hyst_model.effects.shift import shift, shift_columns


def _times(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "uniform":
        return np.arange(n) * 5e-4
    if kind == "jitter":  # a realtime record: periods off by up to 40 %
        return np.cumsum(5e-4 * (1.0 + 0.4 * rng.uniform(-1.0, 1.0, n)))
    t = np.cumsum(rng.uniform(0.0, 1e-3, n))  # repeated stamps included
    t[5:8] = t[5]
    return t


@pytest.mark.parametrize("kind", ["uniform", "jitter", "repeated"])
def test_shift_is_np_interp_bit_for_bit(kind):
    rng = np.random.default_rng(11)
    n = 3000
    t = _times(kind, n, rng)
    v = np.cumsum(rng.normal(size=n))
    v[100] = np.inf  # non-finite values take np.interp's fallbacks
    v[200:202] = np.nan
    dt = float(np.median(np.diff(t)))
    for tau in (0.0, 0.37 * dt, 3.0 * dt, 14.3 * dt, -2.6 * dt, t[-1] - t[0] + dt, -(t[-1] - t[0]) - dt):
        np.testing.assert_array_equal(shift(t, tau, v), np.interp(t - tau, t, v))
        np.testing.assert_array_equal(shift(t, tau, v, left=-1.5, right=2.5),
                                      np.interp(t - tau, t, v, left=-1.5, right=2.5))
        V = np.column_stack([v, -2.0 * v, rng.normal(size=n)])
        want = np.column_stack([np.interp(t - tau, t, V[:, c]) for c in range(V.shape[1])])
        np.testing.assert_array_equal(shift_columns(t, tau, V), want)


def test_shift_refuses_mismatched_shapes():
    with pytest.raises(ValueError):
        shift(np.arange(5.0), 0.5, np.arange(4.0))
    with pytest.raises(ValueError):
        shift_columns(np.arange(5.0), 0.5, np.zeros((4, 2)))


def test_the_delay_push_is_the_column_by_column_shift():
    """An output-side delay carries Jacobian columns in one pass, as its output carries each column."""
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 5e-4
    J = rng.normal(size=(t.size, 4))
    x = np.cumsum(rng.normal(size=t.size))
    d = Delay({"dt": 5e-4, "delay.side": "output"})
    theta = np.array([3.4e-3])
    y = d.output(theta, t, None, x)
    got = push_through(d, theta, t, None, x, y, J)
    want = np.column_stack([d.output(theta, t, None, J[:, c]) for c in range(J.shape[1])])
    np.testing.assert_array_equal(got, want)
    assert not np.array_equal(got, J)  # it did shift
