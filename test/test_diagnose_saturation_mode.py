"""A stage mode behind a strong two-sided limit: the diagnosis must find the stage's order (limit, then mode).

The stage is hyst_sim's GMA with 0.19 of the stroke lost at each end (the knees meet at mid-stroke) and a 463 Hz,
ζ 0.043 resonance after the limit — the case that drew seed 208 of bench/bench_robust_family.py, recorded under
the identification excitation. Saturation is named first; on top of it the refit in the stage's order ended at
60 nm (20x the noise) and the mode inside the limit at 9.2 nm, and that model was kept: controllers with it were
44-93x the effect-free stage's error at 30 Hz. Refitted in the stage's order from the other order's values, the
fit reaches the noise floor (ladder._other_order).
"""
from __future__ import annotations

import pytest

pytestmark = pytest.mark.slow
RATE = 2000.0


def test_mode_behind_a_strong_limit_is_fitted_in_the_stages_order():
    from dataclasses import replace

    from hyst_common.profiles import GMA_LIMITS
    from hyst_control.excitation import ExcitationSpec, build_excitation
    from hyst_model.core import stage_model
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.plant import Plant, PlantConfig

    p = stage_model("gma")
    mbw = p.replace(zeta1=p.zeta1 * 1.0546, zeta2=p.zeta2 * 0.8246, y_scale=p.y_scale * 1.0191)
    cfg = PlantConfig.for_profile("gma", rate=RATE, mbw=mbw, seed=208)
    eff = cfg.effects.with_effects(saturation=replace(cfg.effects.saturation, strength=0.1919),
                                   dynamics=replace(cfg.effects.dynamics, strength=462.8, damping=0.0434))
    plant = Plant(replace(cfg, effects=eff))
    ex = build_excitation(ExcitationSpec(v_min=GMA_LIMITS.v_min, v_max=GMA_LIMITS.v_max, dt=1.0 / RATE, seed=208))
    plant.reset(float(ex.u[0]))
    y = plant.run(ex.u).y
    d = diagnose(ex.t, ex.u, y)
    m, th = d.models[d.ladder[-1].model]
    vals = m.unpack(th)
    assert d.ladder[-1].effects == ["saturation", "dynamics"], d.explanation
    assert vals["dynamics.fn"] == pytest.approx(462.8, rel=0.01), vals
    assert d.ladder[-1].rmse < 1.5 * d.noise, d.explanation
