"""The diagnosis fits its candidates side by side (:mod:`hyst_model.diagnose.parallel`); the answer must not depend
on the thread count: every number, the ladder, the final model and the progress lines are those of one thread."""
from __future__ import annotations

import re

import numpy as np
import pytest


@pytest.fixture(scope="module")
def record():
    from hyst_sim.generator import generate_case

    c = generate_case(4200003, "single_large")  # creep; the ladder climbs a second rung and prunes it
    return c.t, c.u, c.y


def _run(record, jobs):
    from hyst_model.diagnose.diagnose import diagnose

    lines: list[str] = []
    d = diagnose(*record, jobs=jobs, progress=lambda msg, **kw: lines.append(re.sub(r", [0-9.]+ s$", "", msg)))
    return d, lines


def test_same_answer_on_one_and_on_several_threads(record):
    d1, l1 = _run(record, 1)
    d3, l3 = _run(record, 3)
    assert len(d1.ladder) >= 3  # the case exercises screens, refits, a second rung and the prune
    assert d1.missing == d3.missing
    assert [(r.model, r.effects, r.rmse, r.rmse_train) for r in d1.ladder] == \
        [(r.model, r.effects, r.rmse, r.rmse_train) for r in d3.ladder]
    assert [(c.effect, c.rmse, c.significant, c.t_stat, c.improvement) for c in d1.candidates] == \
        [(c.effect, c.rmse, c.significant, c.t_stat, c.improvement) for c in d3.candidates]
    m1, th1 = d1.models[d1.ladder[-1].model]
    m3, th3 = d3.models[d3.ladder[-1].model]
    assert m1.config() == m3.config()
    np.testing.assert_array_equal(th1, th3)
    assert l1 == l3
