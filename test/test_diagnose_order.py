"""The diagnosis ladder tries a non-commuting effect in both orders (:func:`hyst_model.diagnose.ladder._other_order`).

The simulated stage applies its bow (asymmetry) before its creep; the ladder finds creep first and used to add
asymmetry outside it only, which leaves an error the record shows (8x the noise floor on a randomised stage).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest


def _diagnose_sim_stage(seed: int, effects: list[str], **strengths):
    """Diagnose (``effects`` only) an identification record of the simulated PEA stage with hidden ``strengths``."""
    from hyst_bringup.loop import SimPlant
    from hyst_control.excitation import ExcitationSpec, build_excitation
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.plant import Plant, PlantConfig

    rate = 2000.0
    cfg = PlantConfig.for_profile("pea", rate=rate, seed=seed)
    eff = cfg.effects
    eff = eff.with_effects(**{k: replace(getattr(eff, k), strength=v) for k, v in strengths.items()})
    plant = SimPlant(Plant(replace(cfg, effects=eff)))
    ex = build_excitation(ExcitationSpec(v_min=0.0, v_max=150.0, dt=1.0 / rate, seed=seed))
    plant.reset(float(ex.u[0]))
    y = np.array([plant.step(float(v)) for v in ex.u])
    return diagnose(ex.t, ex.u, y, effects=effects)


@pytest.fixture(scope="module")
def diagnosis():
    return _diagnose_sim_stage(7, ["creep", "asymmetry"], asymmetry=0.07, creep=0.04)


def test_the_order_the_record_supports_is_kept(diagnosis):
    d = diagnosis
    assert set(d.ladder[-1].effects) == {"creep", "asymmetry"}, d.explanation
    # applied as the stage does: the bow first, its creep after (innermost first)
    assert d.ladder[-1].effects == ["asymmetry", "creep"], [r.model for r in d.ladder]
    assert d.ladder[-1].rmse < 1.5 * d.noise, (d.ladder[-1].rmse, d.noise)
    # the ranking lists them as found (creep first here: it explains more alone); the rung as its model applies them
    assert [c.effect for c in d.candidates[:2]] == ["creep", "asymmetry"]
    assert d.missing == "creep"
    m, _ = d.models[d.ladder[-1].model]
    assert [e.name for e in m.effects] == d.ladder[-1].effects


@pytest.fixture(scope="module")
def behind_a_delay():
    return _diagnose_sim_stage(11, ["delay", "asymmetry"], asymmetry=0.03, delay=6)


def test_an_effects_configuration_is_chosen_again_on_the_rung(behind_a_delay):
    """The stage's bow is quadratic; with a 6-sample delay dominating the base's residual the gain kink screened
    better on the bare base, and the ladder then only had the kink on top of the delay (12x the noise left)."""
    d = behind_a_delay
    assert set(d.ladder[-1].effects) == {"delay", "asymmetry"}, d.explanation
    m, _ = d.models[d.ladder[-1].model]
    assert m.config().get("asymmetry.form") == "quadratic", m.config()
    assert d.ladder[-1].rmse < 1.5 * d.noise, (d.ladder[-1].rmse, d.noise)


def test_a_kink_behind_creep_is_started_from_the_rungs_own_residual():
    """Generated PEA stage 3000102 (steps): log creep and a gain kink. On the creep rung the kink was started only
    from its values refitted with the base alone and from the bare base, its level and slope read off a residual
    full of creep transients: its screen ended at 31-39 nm, worse than the rung's 17.6 nm, and the kink was never
    named (creep + drift). Started also from the rung's own residual it screens at 13.4 nm and is named."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case

    c = generate_case(3000102, "pair")
    assert set(c.expected) == {"creep", "asymmetry"}
    d = diagnose(c.t, c.u, c.y)
    assert {"creep", "asymmetry"} <= set(d.ladder[-1].effects), d.explanation
    assert d.ladder[-1].rmse < 1.5 * d.noise, d.explanation
