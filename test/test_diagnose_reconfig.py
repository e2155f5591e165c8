"""The configuration step after the ladder (hyst_model.diagnose.reconfig).

Robust-family stage 2312 (``bench/bench_robust_family.py``): a PEA with a quadratic sensor bow (asymmetry 6.8 % of
the stroke) and a soft stop at the top (saturation 13 %). At the first rung asymmetry was taken as a gain kink
(117 nm against 175 nm for the quadratic: the kink bends where the stop does too), the stop joined it, and the
diagnosis ended at 25 nm, 10x the noise floor, in the kink; every law then tracked 2.8-25x worse than on the stage
without the effects. With the quadratic, the same two effects reach the floor.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytestmark = pytest.mark.slow

RATE = 2000.0


def _record(seed: int):
    """The identification excitation played on stage 2312 (its MBW truth rounded), sensor seed ``seed``."""
    from hyst_common.profiles import PEA_LIMITS
    from hyst_control.excitation import ExcitationSpec, build_excitation
    from hyst_model.core import stage_model
    from hyst_sim.plant import Plant, PlantConfig

    p = stage_model("pea")
    mbw = p.replace(zeta1=0.448, zeta2=5.78e-6, y_scale=5.516e-6)
    cfg = PlantConfig.for_profile("pea", rate=RATE, mbw=mbw, seed=2312 + seed)
    eff = cfg.effects.with_effects(saturation=replace(cfg.effects.saturation, strength=0.131),
                                   asymmetry=replace(cfg.effects.asymmetry, strength=0.0684))
    plant = Plant(replace(cfg, effects=eff))
    ex = build_excitation(ExcitationSpec(v_min=PEA_LIMITS.v_min, v_max=PEA_LIMITS.v_max, dt=1 / RATE,
                                         seed=2312 + seed))
    plant.reset(float(ex.u[0]))
    y = np.array([plant.step(float(v)).y for v in ex.u])
    return ex.t, ex.u, y


def test_a_bow_taken_as_a_kink_beside_a_soft_stop_is_reconfigured():
    from hyst_model.diagnose.diagnose import diagnose

    t, u, y = _record(0)
    d = diagnose(t, u, y)
    assert sorted(d.ladder[-1].effects) == ["asymmetry", "saturation"], d.explanation
    m, th = d.models[d.ladder[-1].model]
    assert m.config()["asymmetry.form"] == "quadratic", m.config()
    asym = next(c for c in d.candidates if c.effect == "asymmetry")
    assert "reconfigured after the ladder (form quadratic)" in asym.evidence, asym.evidence
    assert d.ladder[-1].rmse < 1.5 * d.noise, d.explanation                 # 10x before
    # never backwards, and the rung it replaced is still in the ladder
    assert d.ladder[-1].rmse < min(r.rmse for r in d.ladder[:-1])
    # the model carries over to a fresh record (other noise, other excitation)
    t2, u2, y2 = _record(1)
    warm = int(0.1 * t2.size)
    fresh = float(np.sqrt(np.mean(np.square(y2 - m.simulate(th, t2, u2))[warm:])))
    assert fresh < 2.0 * d.noise, (fresh, d.noise)


def test_nothing_to_reconfigure_with_one_effect():
    """With one effect the first rung compared every configuration on the same footing already."""
    from hyst_model.diagnose.reconfig import reconfigure
    ladder: list = []
    assert not reconfigure(None, ladder, {}, ["asymmetry"], {})  # type: ignore[arg-type]
    assert ladder == []
