"""The caution when the base model does not carry over to the record's own hold-out (diagnose.adequacy)."""
from __future__ import annotations

import re

import numpy as np

from hyst_model.diagnose.adequacy import GENERALISATION_FACTOR, MUST_EXPLAIN_FACTOR, base_caution, held_out_only


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


def _split(n: int = 8000, blocks: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Times (0.5 ms) and a held-out mask of ``blocks`` interleaved blocks holding a quarter of the samples."""
    t = np.arange(n) * 5e-4
    val = np.zeros(n, dtype=bool)
    for k in range(blocks):
        a = k * n // blocks + n // blocks * 3 // 4
        val[a:(k + 1) * n // blocks] = True
    return t, val


def test_a_held_out_only_error_over_a_training_part_at_the_floor_is_located_and_named_no_effect():
    rng = np.random.default_rng(3)
    t, val = _split()
    e = 2e-9 * rng.standard_normal(t.size)
    blk = np.flatnonzero(val)[750:900]          # 75 ms in the fourth held-out block: one event
    e[blk] += 60e-9 * np.exp(-np.arange(blk.size) / 30.0)
    msg = held_out_only("mbw", t, e, val, 2e-9, 1.1, 2.0)
    assert msg is not None
    held = float(np.sqrt(np.mean(e[val] ** 2))) / 2e-9
    assert 2.0 <= held < MUST_EXPLAIN_FACTOR and f"{held:.1f}× the floor" in msg
    a = np.flatnonzero(val)[750]                  # the fourth block's first sample
    assert f"the block {t[a]:.3g}–" in msg and "no effect is named" in msg and "fresh record" in msg
    at = float(re.search(r"largest error [0-9.]+ nm at ([0-9.]+) s", msg).group(1))
    assert abs(at - t[blk[0]]) < 5e-3            # the event's largest error, at its start


def test_no_held_out_only_sentence_when_training_errs_too_or_the_hold_out_error_is_large_or_small():
    rng = np.random.default_rng(4)
    t, val = _split()
    e = 2e-9 * rng.standard_normal(t.size)
    bump = 6e-9 * np.sin(2 * np.pi * 3 * t)       # a stationary error: on training and held-out samples alike
    assert held_out_only("mbw", t, e + bump, val, 2e-9, 1.1, 2.0) is None
    big = e.copy()
    big[val] += 12e-9 * np.sign(np.sin(2 * np.pi * 5 * t[val]))   # ≥ 5× the floor: must stay `unexplained`
    assert held_out_only("mbw", t, big, val, 2e-9, 1.1, 2.0) is None
    assert held_out_only("mbw", t, e, val, 2e-9, 1.1, 2.0) is None  # held out at the floor: nothing to say
