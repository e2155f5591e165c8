"""Configuration step after the ladder, its prune and its exchange: is each effect of the final model in the
configuration the whole model needs?

An effect's configuration (asymmetry as a quadratic or a gain kink, creep as a log law or lags, a delay on the
input or the output, one- or two-sided saturation, a mode's structure) is chosen where the effect joins the
ladder, on what it explains there with every later effect still in the residual. A second effect can make the
first one's other configuration the right one: robust-family stage 2312 (a PEA with a quadratic sensor bow and a
soft stop at the top) took asymmetry as a kink at the first rung (117 nm against 175 nm for the quadratic: the
kink also bends where the stop does), then the stop on top of it, and ended at 25.2 nm, 10× the noise floor;
``hyst fit --effects asymmetry,saturation --config asymmetry.form=quadratic`` reaches 2.08 nm, the floor.
:mod:`.alike` reopens the choice only where the configurations validated alike on the base (they did not here).

So, as :mod:`.swap` exchanges an effect for another, this step exchanges an effect's configuration for another:
the final model refitted with one effect in another configuration, from the final model's values (that effect
from its own data start on the residual of the others) and from the bare base, and taken only when it beats the
final model by the test that admits an effect (``min_factor`` and the paired t) — identification never goes
backwards, and an alike result keeps the configuration the ladder chose. Skipped where the final model already
validates within ``min_factor`` of the noise floor: nothing could pass that test there.
"""
from __future__ import annotations

from typing import cast

import numpy as np

from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .blind import helps
from .parallel import pmap
from .refit import _effect_values, _simulate, paired_t, refit, rmse
from .setup import Rung, Setup
from .stages import effect_order, effect_variants, own_config, refit_from_final, variant_suffix

__all__ = ["reconfigure", "other_configurations"]


def other_configurations(s: Setup, m: Model) -> list[tuple[str, dict]]:
    """``(effect, variant)`` for every configuration of each effect of ``m`` other than the one it has (the
    user's fixed keys respected: :func:`~.stages.effect_variants`)."""
    out = []
    for nm in effect_order(m):
        now = own_config(m, nm)
        for var in effect_variants(s, nm):
            if var and any(now.get(k) != v for k, v in var.items()):
                out.append((nm, var))
    return out


def reconfigure(s: Setup, ladder: list, models: dict[str, tuple[Model, np.ndarray]], chosen: list, cands: dict
                ) -> bool:
    """Refit the final rung with each of its effects in each other configuration; take the best one that beats
    it significantly. Returns whether the configuration changed (a rung with the new model is then appended to
    ``ladder``, its model to ``models``, the effect's configuration to ``s.cfg`` and a note to its candidate).

    Only models with two or more effects are examined: with one, the first rung compared every configuration
    of every effect on the same footing already.
    """
    if len(chosen) < 2:
        return False
    t, u, y, val, train = s.t, s.u, s.y, s.val, s.train
    m_full, th_full = models[ladder[-1].model]
    e_full = y - _simulate(m_full, th_full, t, u)
    r_full = rmse(e_full[val])
    if r_full <= s.min_factor * s.noise:  # no model validates below the floor: none could pass the test
        return False
    full_c = cast(ComposedModel, m_full)
    applied = effect_order(m_full)
    values = full_c.unpack(th_full)
    cfg = {k: v for nm in applied for k, v in own_config(m_full, nm).items()}
    items = [(nm, var, route) for nm, var in other_configurations(s, m_full) for route in ("final", "base")]
    if not items:
        return False

    def one(own: Setup, item: tuple[str, dict, str]):
        nm, var, route = item
        own.cfg.update(cfg)
        own.cfg.update(var)
        try:
            if route == "final":  # the others at their final values, nm from its data start on their residual
                start = {k: v for k, v in values.items() if not k.startswith(nm + ".")}
                mm, th, yh = refit_from_final(own, applied, start, full_c, th_full)
            else:
                mm, th, yh = refit(own.base_model, applied, own.cfg, t, u, y, own.th_base, fitter=own.fit)
        except (EffectError, FitError):
            return None
        e = y - yh
        r = rmse(e[val])
        own.say(f"reconfigure {nm}{variant_suffix(var)} in {mm.name} from the {route}: validation RMSE "
                f"{fmt_len(r)} against {fmt_len(r_full)}", step=False)
        return r, nm, var, mm, th, e

    trials = [x for x in pmap(s, one, items) if x is not None and np.isfinite(x[0])]
    better = [x for x in trials if helps(s, val, e_full, x[5])]  # the test that admits an effect
    if not better:
        return False
    r, nm, var, mm, th, e = min(better, key=lambda x: x[0])
    t_stat = paired_t(e_full[val], e[val])
    c = cands[nm]
    c.params = _effect_values(mm, th, nm)
    c.note = ((c.note + "; ") if c.note else "") + (
        f"reconfigured after the ladder{variant_suffix(var)}: {mm.name} validates at {fmt_len(r)} against "
        f"{fmt_len(r_full)} in the configuration the ladder chose (paired t {t_stat:.1f})")
    s.cfg.update(own_config(mm, nm))
    ladder.append(Rung(mm.name, effect_order(mm), r, rmse(e[train])))
    models[mm.name] = (mm, th)
    return True
