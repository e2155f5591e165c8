"""The caution when the base model does not carry over to the record's own hold-out (diagnose.adequacy)."""
from __future__ import annotations

import numpy as np

from hyst_model.diagnose.adequacy import GENERALISATION_FACTOR, base_caution


def _steps(n: int = 4000, k: int = 5) -> np.ndarray:
    return np.repeat(np.linspace(0.0, 100.0, k), n // k)


def test_a_base_that_errs_far_more_on_the_hold_out_gets_a_caution_naming_the_steps():
    msg = base_caution("mbw", 40e-9, 3e-9, 2e-9, _steps(), 2.0)
    assert msg is not None
    assert "13.3× more on the held-out samples" in msg and "4 input changes" in msg and "fresh record" in msg


def test_a_base_that_carries_over_gets_none():
    u = np.sin(np.linspace(0, 20, 4000))
    assert base_caution("mbw", 2.5 * 3e-9, 3e-9, 2e-9, u, 2.0) is None  # 2.5× < GENERALISATION_FACTOR
    assert GENERALISATION_FACTOR > 2.5


def test_a_hold_out_error_near_the_noise_floor_gets_none_whatever_the_ratio():
    # trained to below the noise (over-fitted noise), held out at 1.5× the floor: nothing to caution about
    assert base_caution("mbw", 3e-9, 0.5e-9, 2e-9, _steps(), 2.0) is None


def test_the_ratio_is_taken_against_the_noise_floor_when_training_fits_below_it():
    # training 0.1 nm below a 2 nm floor: the ratio is 8 nm / 2 nm = 4, not 80
    msg = base_caution("mbw", 8e-9, 0.1e-9, 2e-9, np.sin(np.linspace(0, 20, 4000)), 2.0)
    assert msg is not None and "4.0× more" in msg and "input changes" not in msg  # a moving record: no step count


def test_non_finite_errors_give_none():
    assert base_caution("mbw", float("nan"), 1e-9, 1e-9, _steps(), 2.0) is None
