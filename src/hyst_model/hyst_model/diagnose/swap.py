"""Exchange step after the ladder and its prune (:func:`hyst_model.diagnose.prune.prune`): is each effect of the
final model the simplest one that does its job?

The ladder decides its first rung with every other effect still in the residual. With two effects present the
first pick can be one that also soaks up part of the second: on a generated sweep with a sensor delay and a linear
drift, a 3-parameter mode (11.7 nm) beat the 1-parameter delay (13.8 nm) at the first rung because it also bent
towards the drift; drift then took the model to the noise floor (1.64 nm) on top of the mode, and the delay, which
adds nothing on top of a mode, was never tried with the drift. Stepwise regression's exchange step answers this:
each effect of the final model is replaced in turn by each candidate that was significant on its own, the rest
refitted from the final model's values, and the replacement is taken when it validates as well (the test that
admits an effect, ``min_factor`` and the paired t, does not tell them apart) with fewer parameters, or passes that
test against the model. Identification never goes backwards: a replacement is never worse on validation than the
model it replaces by more than that test allows.
"""
from __future__ import annotations

from typing import cast

import numpy as np

from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .ladder import effect_order
from .parallel import pmap
from .refit import _effect_values, _simulate, paired_t, rmse
from .setup import Rung, Setup
from .stages import own_config, refit_from_final, validate_alike

__all__ = ["swap", "alone_significant"]


def alone_significant(s: Setup, full: dict) -> list[str]:
    """Effects whose joint refit with the base alone (``full``: name -> (model, θ, residual)) passes the test
    that admits an effect at the first rung (``min_factor`` and the paired t against the base)."""
    out = []
    for nm, (_, _, e) in full.items():
        r = rmse(e[s.val])
        if r > 0 and s.base_val / r >= s.min_factor and paired_t(s.e_base[s.val], e[s.val]) >= s.t_min:
            out.append(nm)
    return out


def swap(s: Setup, ladder: list, models: dict[str, tuple[Model, np.ndarray]], chosen: list, cands: dict,
         full: dict) -> tuple[list, bool]:
    """Replace an effect of the final rung by a simpler (or significantly better) one; returns (effects, changed).

    Only models with two or more effects are examined (with one, the first rung compared every candidate on
    the same footing already: :func:`~hyst_model.diagnose.ladder.prefer_simpler`). On a replacement, the
    candidates' ``significant`` flags and notes say what was exchanged and why, and a rung with the new model is
    appended to ``ladder`` (its model to ``models``).
    """
    if len(chosen) < 2:
        return chosen, False
    t, u, y, val, train = s.t, s.u, s.y, s.val, s.train
    m_full, th_full = models[ladder[-1].model]
    full_c = cast(ComposedModel, m_full)
    e_full = y - _simulate(m_full, th_full, t, u)
    r_full = rmse(e_full[val])
    applied = effect_order(m_full)
    values = full_c.unpack(th_full)
    alts = [nm for nm in alone_significant(s, full) if nm not in chosen]
    items = [(k, a) for k in chosen for a in alts]
    if not items:
        return chosen, False

    def exchange(own: Setup, item: tuple[str, str]):
        k, a = item
        m_alt, th_alt, _ = full[a]
        own.cfg.update(own_config(m_alt, a))  # the configuration it was significant in
        names = [a if x == k else x for x in applied]
        alt_vals = _effect_values(m_alt, th_alt, a)
        start = {**{x: v for x, v in values.items() if not x.startswith(k + ".")}, **alt_vals}
        try:
            mm, th, yh = refit_from_final(own, names, start, full_c, th_full, prior=alt_vals)
        except (EffectError, FitError):
            return None
        e = y - yh
        own.say(f"exchange {k} for {a}: {mm.name} validates at {fmt_len(rmse(e[val]))}", step=False)
        return rmse(e[val]), k, a, mm, th, e

    trials = [x for x in pmap(s, exchange, items) if x is not None]
    # The final model and every exchange on one footing: the best by validation RMSE, and among those it does
    # not beat by the test that admits an effect (``min_factor`` and the paired t), the fewest parameters (then
    # the lower RMSE). The margin matters: far from the noise floor two models 2 % apart can differ by a large
    # t (a hard saturation + sensor delay at 100x the noise: the delay exchanged for a mode at 123 vs 125 nm).
    options = [(r_full, "", "", m_full, th_full, e_full)] + trials
    best = min(range(len(options)), key=lambda i: options[i][0])
    r_b, e_b = options[best][0], options[best][5]
    alike = [i for i in range(len(options))
             if i == best or validate_alike(s, options[i][0], r_b, paired_t(options[i][5][val], e_b[val]))]
    pick = min(alike, key=lambda i: (len(options[i][3].names), options[i][0], i))
    if pick == 0:
        return chosen, False
    r, k, a, mm, th, e = options[pick]
    t_stat = paired_t(e[val], e_full[val])
    why = (f"{'+'.join([s.base] + [a if x == k else x for x in chosen])} validates at {fmt_len(r)} against "
           f"{fmt_len(r_full)} with {k} (paired t {t_stat:.1f}; {len(mm.names)} parameters against "
           f"{len(m_full.names)})")
    ck, ca = cands[k], cands[a]
    ck.significant = False
    ck.note = f"exchanged for {a} after the ladder: {why}"
    m_alt, th_alt, e_alt = full[a]
    # ``a`` is reported as it was tested on its own (significant there), with the exchange that took it
    ca.on_top_of, ca.rmse, ca.rmse_train = [], rmse(e_alt[val]), rmse(e_alt[train])
    ca.improvement = s.base_val / ca.rmse if ca.rmse > 0 else float("inf")
    ca.t_stat, ca.significant = paired_t(s.e_base[val], e_alt[val]), True
    ca.params = _effect_values(mm, th, a)
    ca.note = f"taken in place of {k} after the ladder: {why}"
    s.cfg.update(own_config(mm, a))
    ladder.append(Rung(mm.name, effect_order(mm), r, rmse(e[train])))
    models[mm.name] = (mm, th)
    return [a if x == k else x for x in chosen], True
