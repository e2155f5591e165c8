"""A rung refitted with a carried effect in another configuration that validated alike on the base.

An effect's configurations (creep as a log law or as two lags, one or two modes, ...) are chosen where the
effect joins the ladder, on what it adds there. Two that validate alike there (within ``min_factor``) are a
choice the record could not make yet, and the one kept can be the wrong basin for the effect added next:
robust-family stage 1905 (log-law creep and an 829 Hz mode of ζ 0.033) kept creep as two lags (64.0 nm against
66.2 nm for the log law, 26× the noise floor either way), and the mode on top of it reached only 42.8 nm (18×
the noise floor); the log law with the mode on top of it reaches the floor (2.18 nm). Refitting the whole rung
from the bare base in the other configuration does not find it (46.5 nm): the route is the one the ladder
itself takes — the other configuration's own fit, then the new effect on top of it.
"""
from __future__ import annotations

import numpy as np

from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .refit import _effect_values, _point, guarded_refit, rmse
from .stages import Setup, effect_order, own_config, variant_suffix

__all__ = ["alike_refits"]


def alike_refits(own: Setup, entry: tuple, cands: dict) -> tuple[Model, np.ndarray, np.ndarray] | None:
    """The best refit of a rung's refit ``entry`` (validation RMSE, new effect, model, θ, residual) with one
    carried effect in another configuration of its :attr:`~.stages.Candidate.alike`: from that configuration's
    own values (base and effect), the other carried effects' and the new effect's values from ``entry``.
    ``None`` when no carried effect has another alike configuration or every such refit failed."""
    t, u, y, val = own.t, own.u, own.y, own.val
    _, new, mm, tth, _ = entry
    names = effect_order(mm)
    vals = _effect_values(mm, tth)
    best = None
    for x in names:
        c = cands.get(x)
        if x == new or c is None:  # the new effect's configurations were screened on the rung already
            continue
        now = own_config(mm, x)
        for var, start in c.alike:
            if not any(now.get(k) != v for k, v in var.items()):
                continue
            for nm in names:
                own.cfg.update(own_config(mm, nm))
            own.cfg.update(var)
            mine = {k: v for k, v in start.items() if k.startswith(x + ".")}
            carry = {**{k: v for k, v in vals.items() if not k.startswith(x + ".")}, **mine}
            base_vals = {k: v for k, v in start.items() if "." not in k}
            try:
                m2, th2, yh2 = guarded_refit(own.base_model, names, own.cfg, t, u, y, val, {**base_vals, **carry},
                                             theta_base=_point(own.base_model, base_vals), carry=carry,
                                             fitter=own.fit)
            except (EffectError, FitError):
                continue
            r2 = rmse((y - yh2)[val])
            own.say(f"refit {m2.name}{variant_suffix(var)} from its own fit: validation RMSE {fmt_len(r2)}")
            if best is None or r2 < best[0]:
                best = (r2, m2, th2, y - yh2)
    return None if best is None else best[1:]
