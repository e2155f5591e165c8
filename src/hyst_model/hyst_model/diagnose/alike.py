"""A rung refitted with a carried effect in another configuration that validated alike on the base.

An effect's configurations (creep as a log law or as two lags, one or two modes, ...) are chosen where the
effect joins the ladder, on what it adds there. Two that validate alike there (within ``min_factor``) are a
choice the record could not make yet, and the one kept can be the wrong basin for the effect added next:
robust-family stage 1905 (log-law creep and an 829 Hz mode of ζ 0.033) kept creep as two lags (64.0 nm against
66.2 nm for the log law, 26× the noise floor either way), and the mode on top of it reached only 42.8 nm (18×
the noise floor); the log law with the mode on top of it reaches the floor (2.18 nm). Refitting the whole rung
from the bare base in the other configuration does not find it (46.5 nm): the route is the one the ladder
itself takes — the other configuration's own fit, then the new effect on top of it.

The choice is open wider than ``min_factor`` while the best configuration leaves error above the noise floor:
what another effect explains can tip it. Generated GMA stage 3600018 (two-lag creep and a 9x-noise input delay,
triangles) kept creep as two lags (7.92 nm against 9.69 nm for the log law, 3x the noise floor); the delay on top
of it reached 5.49 nm, drift was taken instead (3.97 nm on validation but 20.7 nm on training) and the model left
7.5x the noise on a fresh record. The log law with the delay, refitted from the bare base, reaches 3.49 nm on
both parts and 1.1x on the fresh record; from its own fit only 6.39 nm — so both routes are tried.
"""
from __future__ import annotations

import numpy as np

from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .parallel import pmap
from .refit import _effect_values, _point, guarded_refit, refit, rmse
from .setup import Setup
from .stages import effect_order, n_params, own_config, variant_suffix

__all__ = ["alike_refits", "simpler_alike"]


def alike_refits(own: Setup, entry: tuple, cands: dict) -> tuple[Model, np.ndarray, np.ndarray] | None:
    """The best refit of a rung's refit ``entry`` (validation RMSE, new effect, model, θ, residual) with one
    carried effect in another configuration of its :attr:`~.setup.Candidate.alike`: from that configuration's
    own values (base and effect), the other carried effects' and the new effect's values from ``entry``; and from
    the bare base, every effect from its own data start.
    ``None`` when no carried effect has another alike configuration or every such refit failed."""
    t, u, y, val = own.t, own.u, own.y, own.val
    _, new, mm, tth, _ = entry
    names = effect_order(mm)
    vals = _effect_values(mm, tth)
    cfg = {k: v for nm in names for k, v in own_config(mm, nm).items()}
    # (route, variant, base values, effect values) in the order they are judged; no values: from the bare base
    jobs: list[tuple[str, dict, dict | None, dict | None]] = []
    for x in names:
        c = cands.get(x)
        if x == new or c is None:  # the new effect's configurations were screened on the rung already
            continue
        now = own_config(mm, x)
        for var, start in c.alike:
            if any(now.get(k) != v for k, v in var.items()):
                mine = {k: v for k, v in start.items() if k.startswith(x + ".")}
                carry = {**{k: v for k, v in vals.items() if not k.startswith(x + ".")}, **mine}
                base_vals = {k: v for k, v in start.items() if "." not in k}
                # from that configuration's own values; and from the bare base, every effect from its own data
                # start (the route that found 3600018)
                jobs.append(("its own fit", var, base_vals, carry))
                jobs.append(("the base", var, None, None))

    def one(job_s: Setup, job: tuple[str, dict, dict | None, dict | None]):
        route, var, base_vals, carry = job
        job_s.cfg.update(cfg)
        job_s.cfg.update(var)
        try:
            if base_vals is not None and carry is not None:
                return route, *guarded_refit(
                    job_s.base_model, names, job_s.cfg, t, u, y, val, {**base_vals, **carry},
                    theta_base=_point(job_s.base_model, base_vals), carry=carry, fitter=job_s.fit)
            return route, *refit(job_s.base_model, names, job_s.cfg, t, u, y, own.th_base, fitter=job_s.fit)
        except (EffectError, FitError):
            return None

    best = None
    # side by side: a rung's retries often hold one entry, and its refits are independent (:func:`pmap`)
    for job, res in zip(jobs, pmap(own, one, jobs)):
        if res is None:
            continue
        route, m2, th2, yh2 = res
        r2 = rmse((y - yh2)[val])
        own.say(f"refit {m2.name}{variant_suffix(job[1])} from {route}: validation RMSE {fmt_len(r2)}")
        if best is None or r2 < best[0]:
            best = (r2, m2, th2, y - yh2)
    return None if best is None else best[1:]


def simpler_alike(s: Setup, results: list, best: tuple) -> list[tuple[dict, dict]]:
    """``(values, configuration)`` of the screens of one effect on a rung — ``(RMSE, name, values, full, var)``
    each, with the rung held fixed — that validated within ``min_factor`` of the best one's with fewer
    parameters.

    A screen with the rung held fixed cannot judge a configuration by its parameters
    (:func:`~.ladder._rung_variants`): on a randomised GMA stage (2210: a 583 Hz mode behind a 6-sample delay)
    the mode screened on the delay rung at 9.78 nm with one mode and 9.77 nm with the two in force; refitted
    with two it stopped at 2.97 nm in a basin a second, near-Nyquist "mode" made, while one mode refits to
    2.11 nm — the stage itself — and only one mode has an inverse the controllers can run. Such a configuration
    is refitted too (:func:`~.ladder.climb`) and kept unless the richer one validates better by the standard an
    effect must meet (:func:`~.stages._better_config`, as on the base).
    """
    nm, var_b = best[1], best[4]

    k_b = n_params(s, nm, var_b)
    if k_b is None:
        return []
    out = []
    for res in results:
        r, _, vals, _, var = res
        if res is not best and np.isfinite(r) and r <= s.min_factor * best[0]:
            kv = n_params(s, nm, var)
            if kv is not None and kv < k_b:
                out.append((vals, var))
    return out
