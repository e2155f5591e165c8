"""The backward step keeps an effect the hold-out does not exercise but the training part needs.

Generated GMA stage 3200175 (seed 32 of bench/bench_diagnose_accuracy.py, triangles): a warm-up drift and a hard
stop at 12.8 µm that only training samples reach (the hold-out peaks at 12.4 µm). The ladder found saturation and
drift (1.03× the noise floor on validation); the backward step dropped the stop because without it the drift model
validated exactly as well — while its training error rose from 1.2× to 60× the floor, and on the fresh record,
which reaches the stop, the answer was 54× the floor. The step now asks the training part too (prune).
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_a_stop_only_training_reaches_is_not_pruned():
    from hyst_model.diagnose.diagnose import diagnose, validation_mask
    from hyst_sim.generator import generate_case

    c = generate_case(3200175, "pair")
    assert set(c.expected) == {"drift", "saturation"}
    val = validation_mask(c.t.size, c.u)
    assert c.y[~val].max() > c.y[val].max() + 0.2e-6  # the premise: the stop is reached in training only
    d = diagnose(c.t, c.u, c.y)
    assert set(d.ladder[-1].effects) == {"drift", "saturation"}, d.explanation
    assert d.ladder[-1].rmse_train < 2.0 * d.noise, d.explanation
    fm, fth = d.models[d.ladder[-1].model]
    warm = int(0.1 * c.t.size)
    e_fresh = np.sqrt(np.mean((c.y_fresh - fm.simulate(fth, c.t_fresh, c.u_fresh))[warm:] ** 2))
    assert e_fresh < 3.0 * d.noise, e_fresh / d.noise
