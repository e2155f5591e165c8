"""A stage mode behind creep: the diagnosis must keep the mode it found, not a slow look-alike.

The stage (hyst_sim's PEA with creep 0.047 per decade and a 520 Hz, ζ 0.08 resonance, the case that drew seed
402 of bench/bench_robust_family.py) is recorded under the identification excitation (what hyst_excite_node
plays). Creep is named first; on top of it the joint refit carrying the rung's values settled on an overdamped
21 Hz "mode" (39.7 nm on validation) while a screen refitted from the base had reached the noise floor with the
true mode: the ladder now never goes back from a model already found. Controllers given the 21 Hz model were
200x the effect-free stage's error; given the found mode, at its level.
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.slow
RATE = 2000.0


def test_mode_behind_creep_is_found_not_a_slow_look_alike():
    from dataclasses import replace

    from hyst_common.profiles import PEA_LIMITS
    from hyst_control.excitation import ExcitationSpec, build_excitation
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.plant import Plant, PlantConfig

    cfg = PlantConfig.for_profile("pea", rate=RATE, seed=402)
    eff = cfg.effects.with_effects(creep=replace(cfg.effects.creep, strength=0.047),
                                   dynamics=replace(cfg.effects.dynamics, strength=520.0, damping=0.08))
    plant = Plant(replace(cfg, effects=eff))
    ex = build_excitation(ExcitationSpec(v_min=PEA_LIMITS.v_min, v_max=PEA_LIMITS.v_max, dt=1.0 / RATE, seed=402))
    plant.reset(float(ex.u[0]))
    y = plant.run(ex.u).y
    d = diagnose(ex.t, ex.u, y)
    m, th = d.models[d.ladder[-1].model]
    vals = m.unpack(th)
    assert {"creep", "dynamics"} <= set(d.ladder[-1].effects), d.explanation
    assert vals["dynamics.fn"] == pytest.approx(520.0, rel=0.05), vals
    assert d.ladder[-1].rmse < 3.0 * d.noise, d.explanation
    assert np.isfinite(d.ladder[-1].rmse)
