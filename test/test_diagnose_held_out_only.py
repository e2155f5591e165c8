"""A record without an effect whose base errs only where the hold-out goes beyond training is answered ``none``.

Generated GMA stage 5200178 (seed 52 of bench/bench_diagnose_accuracy.py, a mix, no effect): the base fits its
training samples at 1.00× the noise floor and its held-out ones at 2.15×, 98 % of that in the 40 ms after the
record's one full-range step, which fell in a held-out block. No candidate explained it and the answer was
``unexplained`` — a false alarm (on the fresh record the base predicted at the floor). A missing effect would
leave an error on the interleaved training samples too (:func:`hyst_model.diagnose.adequacy.held_out_only`).
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_a_base_erring_at_one_held_out_event_only_names_no_effect_and_says_where():
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case

    c = generate_case(5200178, "none")
    assert c.expected == ("none",)
    d = diagnose(c.t, c.u, c.y)
    # the premise: training at the floor, the hold-out above twice the floor but below the 5×
    assert d.baseline_rmse_train < 1.1 * d.noise and 2.0 * d.noise <= d.baseline_rmse < 5.0 * d.noise
    assert d.missing == "none" and d.unexplained is None, d.explanation
    assert d.caution is not None and "does not determine the base" in d.caution
    assert "of the held-out excess lies in the block 2.75" in d.explanation, d.explanation
    assert not any(x.significant for x in d.candidates)
    bm, bth = d.models[d.base]
    warm = int(0.1 * c.t.size)
    fresh = np.sqrt(np.mean((c.y_fresh - bm.simulate(bth, c.t_fresh, c.u_fresh))[warm:] ** 2))
    assert fresh < 1.25 * c.noise, fresh / c.noise   # the base was right: nothing was missing
