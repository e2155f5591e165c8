"""Backward elimination after the forward ladder of :func:`hyst_model.diagnose.ladder.climb`.

The ladder adds effects greedily: the first effect is the one that explains most of the error on its own, the
second the one that helps most on top of it. With two effects present, an effect taken early can stand in for
part of another (a symmetric soft saturation's bow looks like asymmetry, a drift's trend like creep) and stay in
the ladder after the true pair has been found. Stepwise regression answers this with a backward step: each
effect of the final rung is dropped in turn, the rest refitted from the final model's values, and an effect whose
removal the full model does not beat significantly (the same test that admitted it: ``min_factor`` and the
paired t over the validation chunks) is removed — unless the training part, which the hold-out may not cover
where the effect acts, needs it by the same test (:func:`_needed_in_training`). Identification never goes
backwards: the pruned model is at most a significance test worse on validation than the full one, and it has
fewer parameters.
"""
from __future__ import annotations

from typing import cast

import numpy as np

from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .blind import helps
from .ladder import effect_order
from .parallel import pmap
from .refit import _simulate, paired_t, rmse
from .setup import Rung, Setup
from .stages import refit_from_final

__all__ = ["prune"]


def prune(s: Setup, ladder: list, models: dict[str, tuple[Model, np.ndarray]], chosen: list, cands: dict
          ) -> list:
    """Drop effects of the final rung that the others make unnecessary; returns the effects kept (in ladder order).

    A dropped effect's candidate gets ``significant = False`` and a note saying why; a final rung with the kept
    effects is appended to ``ladder`` (its model to ``models``), so the ladder shows the path and the answer.
    """
    for c in cands.values():  # set anew by the last round below, on the final model only
        c.rmse_without = None
    if len(chosen) < 2:
        return chosen
    t, u, y, val, train = s.t, s.u, s.y, s.val, s.train
    kept = list(chosen)
    m_full, th_full = models[ladder[-1].model]
    e_full = y - _simulate(m_full, th_full, t, u)
    r_full = rmse(e_full[val])
    changed = False
    while len(kept) >= 2:
        full_c = cast(ComposedModel, m_full)
        values = full_c.unpack(th_full)
        applied = effect_order(m_full)  # refits keep the order the model applies its effects in

        def without(own: Setup, nm: str):
            rest = [k for k in applied if k != nm]
            start = {k: v for k, v in values.items() if not k.startswith(nm + ".")}  # the final point without nm
            try:
                mm, th, yh = refit_from_final(own, rest, start, full_c, th_full, two_stage=False)
            except (EffectError, FitError):
                return None
            e = y - yh
            r = rmse(e[val])
            t_stat = paired_t(e[val], e_full[val])
            own.say(f"prune {m_full.name} - {nm}: validation RMSE {fmt_len(r)} (paired t {t_stat:.1f}), training "
                    f"{fmt_len(rmse(e[train]))} against {fmt_len(rmse(e_full[train]))}", step=False)
            return r, nm, mm, th, e, t_stat

        tried = [x for x in pmap(s, without, kept) if x is not None]
        for k in kept:  # what each adds to this model (kept only if this round is the last)
            cands[k].rmse_without = next((x[0] for x in tried if x[1] == k), None)
        trials = [x for x in tried
                  if r_full > 0 and (x[0] / r_full < s.min_factor or x[5] < s.t_min)
                  and not _needed_in_training(s, x[4], e_full)]
        if not trials:
            break
        r, nm, mm, th, e, t_stat = min(trials, key=lambda x: x[0])
        c = cands[nm]
        c.significant = False
        c.note = (f"dropped again: without it {'+'.join([s.base] + [k for k in kept if k != nm])} validates at "
                  f"{fmt_len(r)} against {fmt_len(r_full)} with it (not significantly worse: ratio "
                  f"{r / r_full:.2f}, paired t {t_stat:.1f}) — the other effects explain what it did")
        kept.remove(nm)
        m_full, th_full, e_full, r_full = mm, th, e, r
        changed = True
        for k in kept:  # measured on the model before this drop
            cands[k].rmse_without = None
    if changed:
        ladder.append(Rung(m_full.name, effect_order(m_full), r_full, rmse(e_full[train])))
        models[m_full.name] = (m_full, th_full)
    return kept


def _needed_in_training(s: Setup, e: np.ndarray, e_full: np.ndarray) -> bool:
    """Whether the training part needs the effect dropped from ``e_full`` (residual ``e`` without it): the same
    test as on validation (``min_factor`` and the paired t), on the samples the models were fitted on.

    The hold-out can miss where an effect acts: generated GMA stage 3200175 (a warm-up drift and a hard stop at
    12.8 µm that only training samples reach; validation peaks at 12.4 µm) — without the stop the drift model
    validated exactly as well (paired t 0.0) and the stop was dropped, while the training error rose from 1.2×
    to 60× the noise floor and the fresh record, which reaches the stop, was 54× the floor (with it 1.0×). An
    effect that merely stands in for another leaves the training fit alike once the others are refitted
    without it."""
    return helps(s, s.train, e, e_full)
