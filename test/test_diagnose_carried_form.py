"""A carried effect's configuration is reopened on a rung while the base left error above the floor.

Generated GMA stage 3600018 (two-lag creep, an input delay at 9x the noise, triangles at several amplitudes).
Creep as two lags screened 1.22x better than the log law on the base, beyond ``min_factor``, so the ladder kept
two lags and never refitted the rung in the log law; the delay on top of it stopped at 5.49 nm, drift was taken
instead (validating alike, 20.7 nm on training) and the final model left 7.5x the noise on a fresh record. The log
law with the delay, refitted from the bare base, reaches the floor on both parts (:mod:`hyst_model.diagnose.alike`).
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_a_delay_behind_creep_is_found_with_creep_in_its_other_form():
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case

    c = generate_case(3600018, "pair")
    assert set(c.expected) == {"creep", "delay"}
    d = diagnose(c.t, c.u, c.y)
    assert {"creep", "delay"} <= set(d.ladder[-1].effects), d.explanation
    m, th = d.models[d.ladder[-1].model]
    assert m.config()["creep.form"] == "log", m.config()  # the form the delay is found with
    warm = int(0.1 * c.t.size)
    fresh = float(np.sqrt(np.mean(np.square(c.y_fresh - m.simulate(th, c.t_fresh, c.u_fresh))[warm:])))
    assert fresh < 2.0 * c.noise, (fresh, c.noise, d.explanation)  # 7.5x before; the true effects give 1.4x
