"""The interleaved hold-out sees a fair share of the record's input changes (identify.result.block_phase)."""
from __future__ import annotations

import numpy as np
import pytest

from hyst_model.identify import block_mask
from hyst_model.identify.result import block_phase


def _share(u: np.ndarray, mask: np.ndarray) -> float:
    a = np.abs(np.diff(u, prepend=u[0]))
    return float(a[mask].sum() / a.sum())


def _steps_in_training(n: int = 16000, seed: int = 3) -> np.ndarray:
    """Holds whose every step lands in the training part of the unshifted grid (its first 5/8 of each segment)."""
    rng = np.random.default_rng(seed)
    seg = n // 8
    u = np.zeros(n)
    level = 0.0
    for j in range(8):
        k = j * seg + int(rng.integers(seg // 8, seg // 2))
        level = float(rng.uniform(-5, 5))
        u[k:] = level
    return u


def test_a_steps_record_whose_steps_all_train_gets_blocks_that_hold_some_of_them():
    u = _steps_in_training()
    plain = block_mask(u.size, 0.25, 8)
    assert _share(u, plain) == 0.0  # the case: the unshifted grid validates no step at all
    m = block_mask(u.size, 0.25, 8, u)
    assert 0.125 <= _share(u, m) <= 0.5
    assert m.sum() == plain.sum()  # the same amount held out, only placed elsewhere
    assert not m[: u.size // 32].any()  # the start from rest still trains


@pytest.mark.parametrize("kind", ["sine", "noise", "sweep"])
def test_records_that_move_throughout_keep_the_unshifted_grid(kind):
    rng = np.random.default_rng(1)
    t = np.arange(12000) * 1e-3
    u = {"sine": np.sin(2 * np.pi * 3 * t), "noise": np.cumsum(rng.standard_normal(t.size)) * 0.01,
         "sweep": np.sin(2 * np.pi * (1 + 4 * t) * t)}[kind]
    assert block_phase(u) == 0.0
    assert np.array_equal(block_mask(u.size, 0.25, 8, u), block_mask(u.size, 0.25, 8))


def test_a_constant_input_keeps_the_unshifted_grid():
    assert block_phase(np.full(5000, 3.0)) == 0.0


def test_the_rmse_of_a_diverging_residual_is_inf_without_a_warning():
    """EPSO's diverging particles printed numpy's 'overflow encountered in multiply' on the user's terminal."""
    import warnings

    from hyst_model.identify.result import rmse

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert rmse(np.array([1e200, -1e200, 0.0])) == np.inf
        assert rmse(np.array([3.0, -3.0])) == 3.0
    assert np.isnan(rmse(np.array([])))
