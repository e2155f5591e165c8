"""Two effects that explain the record only together: the start the error ladder takes when no single one does.

The ladder (:func:`~.ladder.climb`) is forward stepwise selection: it climbs only from an effect that beats the
base on its own. Two effects can each be useless alone and large together — each one's refit with the base
bends the base to stand in for the other, and the hold-out punishes that. Generated PEA stage 4900030 (two
lightly damped modes and a slow drift, on a mixed excitation): the base validated at 280 nm (248× the 1.13 nm
noise floor), mbw+dynamics at 295 nm and mbw+drift at 298 nm on validation (the drift alone trained at 17 nm
against 44 nm), so the answer was ``unexplained``; the two refitted together from the base validate at 23 nm.

Forward selection's known blind spot, closed the usual way: where the answer would otherwise be
``unexplained`` — no effect significant and the base at least ``unexplained_factor`` × the noise floor — every
pair of candidates is refitted jointly with the base (each in the configuration its own refit kept, from its own
refit's values; never worse than that start: :func:`~.refit.guarded_refit`), side by side. The best pair is taken
only when it beats the base *and each of its two single refits* by the test that admits an effect
(``min_factor`` and the paired t, :func:`~.blind.helps`): each of the two is then needed beside the other. The
ladder climbs on from it, and the backward step, the exchange and the configuration step examine it as any
other rung. Records answered otherwise never reach this step, so their answers do not change.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from .blind import helps
from .parallel import pmap
from .refit import _effect_values, guarded_refit, paired_t, rmse
from .setup import Candidate, Setup

__all__ = ["joint_pair"]


def joint_pair(s: Setup, cands: dict[str, Candidate], full: dict, unexplained_factor: float) -> tuple | None:
    """The best pair of effects that explains the record where no single effect does, or ``None``.

    Parameters
    ----------
    s : Setup
    cands : dict
        The candidates after :func:`~.stages.refit_all` (their ``significant`` flags decide whether this runs).
    full : dict
        Each candidate's joint refit with the base: ``name -> (model, θ, residual)``.
    unexplained_factor : float
        The step runs only where the base validates at or above this × the noise floor.

    Returns
    -------
    tuple or None
        ``(validation RMSE, (first, second), model, θ, residual)``, the first being the effect whose own refit
        validated better; the two candidates get a note saying they were taken together.
    """
    if s.at_floor or s.base_val < unexplained_factor * s.noise or any(c.significant for c in cands.values()):
        return None
    names = [nm for nm in s.names if nm in full]
    pairs = list(combinations(names, 2))
    if not pairs:
        return None
    t, u, y, val = s.t, s.u, s.y, s.val
    start_base = s.base_model.unpack(s.th_base)

    def one(own: Setup, pair: tuple[str, str]):
        prior: dict = {}
        for nm in pair:
            prior.update(_effect_values(full[nm][0], full[nm][1], nm))
        try:
            m, th, yh = guarded_refit(own.base_model, list(pair), own.cfg, t, u, y, val, {**start_base, **prior},
                                      theta_base=own.th_base, fitter=own.fit, prior=prior)
        except (EffectError, FitError):
            return None
        e = y - yh
        own.say(f"refit {m.name} jointly (neither alone is significant): validation RMSE {fmt_len(rmse(e[val]))}",
                step=False)
        return rmse(e[val]), pair, m, th, e

    found = [r for r in pmap(s, one, pairs) if r is not None and np.isfinite(r[0])]
    ok = [r for r in found if helps(s, val, s.e_base, r[4])
          and all(helps(s, val, full[nm][2], r[4]) for nm in r[1])]
    if not ok:
        return None
    r, pair, m, th, e = min(ok, key=lambda x: x[0])
    alone = {nm: rmse(full[nm][2][val]) for nm in pair}
    first, second = sorted(pair, key=alone.__getitem__)
    for nm, other in ((first, second), (second, first)):
        cands[nm].note = (f"taken together with {other}: alone neither validates significantly better than the "
                          f"base ({nm} {fmt_len(alone[nm])}, {other} {fmt_len(alone[other])}, base "
                          f"{fmt_len(s.base_val)}), together {fmt_len(r)} (paired t "
                          f"{paired_t(full[nm][2][val], e[val]):.1f} against {nm} alone)")
    return r, (first, second), m, th, e
