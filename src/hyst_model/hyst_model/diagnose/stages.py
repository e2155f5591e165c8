"""The first stages of :func:`hyst_model.diagnose.diagnose.diagnose`: screen → refit (then the ladder, :mod:`.ladder`,
and the answer, :mod:`.verdict`).

Each stage reads the fitted base and the record from a :class:`~.setup.Setup` and returns plain results; the
orchestration (checks, the base fit, the :class:`~hyst_model.diagnose.diagnose.Diagnosis`) is in ``diagnose.py``.
"""
from __future__ import annotations

import math
import time
from typing import cast

import numpy as np

from ..errors import EffectError, FitError
from ..effects import EFFECTS, compose
from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from ..model import Model
from .refit import Fixed, _Progress, _effect_values, _simulate, guarded_refit, paired_t, refit, rmse
from .blind import training_only
from .parallel import pmap
from .setup import Candidate, Setup

__all__ = ["screen_on", "n_params", "screen_all", "refit_all", "rebase", "effect_order", "effect_variants",
           "own_config", "refit_from_final", "validate_alike", "variant_label", "variant_suffix"]


def refit_from_final(s: Setup, names: list, start: dict, final: ComposedModel, th_final: np.ndarray, **kw):
    """The effects ``names`` refitted jointly with the base from the point ``start`` (named values: the final
    model's, changed), never worse on validation than that point (:func:`guarded_refit`); the base starts from the
    final model's base parameters and every effect value in ``start`` is carried. The after-the-ladder steps
    (:mod:`.prune`, :mod:`.swap`) refit this way; ``kw`` goes to :func:`guarded_refit` (``two_stage``, ``prior``).
    """
    return guarded_refit(s.base_model, names, s.cfg, s.t, s.u, s.y, s.val, start,
                         theta_base=final.split(th_final)[0], carry={k: v for k, v in start.items() if "." in k},
                         fitter=s.fit, **kw)


def screen_on(s: Setup, inner: Model, th_inner: np.ndarray, chosen: list, nm: str, prior: dict | None):
    """Fit effect ``nm`` on top of ``inner`` held fixed (its effect parameters + the offset); return
    (validation RMSE, effect values, (model, θ, residual) if it was a full refit else None).

    Effects that say so (:meth:`Effect.screen_with_refit`: they replace the base recursion or transform its
    input, or the base imitates them) get the joint refit instead — with the base held fixed they look useless.
    """
    t, u, y, val = s.t, s.u, s.y, s.val
    if compose(s.base_model, [nm], s.cfg).effects[-1].screen_with_refit():
        # On a rung, from the bare base and from the rung's point (its base parameters and effect values), the
        # best kept: each start alone lost a case — behind a 6-sample delay the quadratic bow refitted from the
        # bare base ended at 1.04 µm against the rung's 48.9 nm (and the kink was kept), while a 520 Hz mode
        # behind creep was found only from the bare base (from the creep rung: a 21 Hz look-alike).
        starts = [(s.th_base, prior)]
        if isinstance(inner, ComposedModel):
            starts.append((inner.split(th_inner)[0], {**_effect_values(inner, th_inner), **(prior or {})}))
            if prior:
                # and from the rung's point with the effect's own start read off the rung's residual (refit's
                # _start_on_carried): the values it took on the base alone can be far from what the rung leaves
                # (generated stage 3000102: a gain kink behind creep screened at 31-39 nm from those, worse than
                # the rung's 17.6 nm; from the rung's residual 13.4 nm, and it was named)
                starts.append((inner.split(th_inner)[0], _effect_values(inner, th_inner)))
        best = None
        for th_b, keep in starts:
            try:
                m, th, yh = refit(s.base_model, chosen + [nm], s.cfg, t, u, y, th_b, keep, s.fit)
            except (FitError, EffectError):
                if len(starts) == 1:
                    raise
                continue
            r = rmse((y - yh)[val])
            if best is None or r < best[0]:
                best = (r, m, th, yh)
        if best is None:
            raise FitError(f"the joint refit with {nm} failed from every start")
        r, m, th, yh = best
        return r, _effect_values(m, th, nm), (m, th, y - yh)
    fx = Fixed(inner, th_inner)
    m = compose(fx, [nm], s.cfg)
    th_data = m.start(t, u, y, fx.theta0)
    starts_fx = [th_data]
    if prior:
        # The values the effect took elsewhere (alone on the base) and its start from this rung's residual, the
        # better kept: the carried values alone can lie where the rung gives no gradient (generated GMA stage
        # 1100030, a gain kink and a soft two-sided limit: the limit alone on the base ended 285 µm below the
        # stroke; carried onto the kink's rung the screen never moved from 37.1 nm, while from the rung's own
        # start the kink + limit reach the noise floor, 3.8 nm).
        th_prior = th_data.copy()
        for k, v in prior.items():
            if k in m.names:
                th_prior[m.names.index(k)] = v
        if not np.array_equal(th_prior, th_data):  # the same start twice would be the same fit twice
            starts_fx.insert(0, th_prior)
    fits = []
    for th0 in starts_fx:
        th = s.fit(m, t, u, y, np.clip(th0, *m.bounds))
        fits.append((rmse((y - _simulate(m, th, t, u))[val]), th))
    r, th = min(fits, key=lambda f: f[0])  # the first on a tie
    vals = _effect_values(m, th, nm)
    if "offset" in m.names:  # the screen refits the offset too: part of the point a refit starts from
        vals["offset"] = float(th[m.names.index("offset")])
    return r, vals, None


def variant_suffix(var: dict) -> str:
    """`` (form kink)`` for ``{"asymmetry.form": "kink"}``; empty for an effect with one configuration."""
    return f" ({variant_label(var)})" if var else ""


def variant_label(vv: dict) -> str:
    """``structure series, modes 2`` for ``{"dynamics.structure": "series", "dynamics.modes": 2.0}``."""
    return ", ".join(f"{k.split('.', 1)[-1]} {v:g}" if isinstance(v, float) else f"{k.split('.', 1)[-1]} {v}"
                     for k, v in vv.items())


def screen_all(s: Setup) -> tuple[dict, dict, dict]:
    """Stage 1: each candidate alone on top of the fitted base, in each of its variants (the better kept).

    Returns ``(candidates, carry, full)``: Candidate by name; each one's fitted effect values (the point its
    refit starts from); and (model, θ, residual) of candidates whose screen already was a joint refit. Every
    variant of every candidate is screened side by side (:func:`~.parallel.pmap`: dynamics' feedback structure
    alone took 3 of the 5 s this stage took on 60k samples); ``s.cfg`` takes each one's kept variant.
    """
    cands: dict[str, Candidate] = {}
    carry: dict[str, dict] = {}
    full: dict[str, tuple] = {}
    items = [(nm, i, v) for nm in s.names for i, v in enumerate(effect_variants(s, nm))]
    done_by: dict[str, list] = {}
    for (nm, _, _), res in zip(items, pmap(s, _screen_variant, items, cost=lambda it: _sim_cost(s, it))):
        done_by.setdefault(nm, []).append(res)
    for nm in s.names:
        cand, vals, done, var = _screened(s, nm, done_by[nm])
        cands[nm] = cand
        if vals is not None:
            s.cfg.update(var)
            carry[nm] = vals
        if done is not None:
            full[nm] = done
    return cands, carry, full


def effect_variants(s: Setup, nm: str) -> list[dict]:
    """The configurations effect ``nm`` is tried in (:meth:`Effect.variants`), without those that would change
    a key the user fixed; ``[{}]`` for an effect with one configuration."""
    variants = list(getattr(EFFECTS[nm], "variants", lambda: [{}])()) or [{}]
    return [v for v in variants if not any(k in s.fixed and s.fixed[k] != x for k, x in v.items())] or [{}]


def n_params(s: Setup, nm: str, var: dict | None = None) -> int | None:
    """Free parameters effect ``nm`` adds in its configuration on ``s.cfg`` (with ``var`` over it); ``None`` where
    that configuration cannot be composed."""
    try:
        return len(compose(s.base_model, [nm], {**s.cfg, **(var or {})}).effects[-1].params())
    except EffectError:
        return None


def effect_order(m: Model) -> list[str]:
    """The effects of ``m`` in the order it applies them (innermost first); none for a bare base model."""
    return [e.name for e in m.effects] if isinstance(m, ComposedModel) else []


def own_config(m: Model, nm: str) -> dict:
    """The configuration keys of effect ``nm`` in the composed model ``m`` (the variant it was fitted in)."""
    return {k: v for k, v in m.config().items() if k.startswith(nm + ".")} if hasattr(m, "config") else {}


def _sim_cost(s: Setup, item: tuple[str, int, dict]) -> float:
    """Seconds one simulation of base + the variant takes at its defaults: the order the screens are started in
    (the slowest first; the results do not depend on it)."""
    nm, _, var = item
    try:
        m = compose(s.base_model, [nm], {**s.cfg, **var})
        tc = time.perf_counter()
        m.simulate(m.theta0, s.t, s.u)
        return time.perf_counter() - tc
    except Exception:  # noqa: BLE001 - only a scheduling hint; the screen itself reports the failure
        return 0.0


def _screen_variant(s: Setup, item: tuple[str, int, dict]) -> dict:
    """One variant of one candidate (on this task's copy of the configuration): its screen, or why it failed;
    the first variant also takes the residual signature."""
    nm, i, var = item
    tc = time.perf_counter()
    out: dict = {"var": var}
    if i == 0:
        probe = compose(s.base_model, [nm], s.cfg)
        try:
            score, ev = probe.effects[-1].signature(s.t, s.u, s.e_base, s.dt)
            out["score"], out["ev"] = float(np.clip(score, 0.0, 1.0)), ev
        except Exception as err:  # noqa: BLE001 - a user effect's test must not sink the diagnosis
            out["score"], out["ev"] = 0.0, f"its residual test failed ({type(err).__name__}: {err})"
    s.cfg.update(var)  # an effect reads only its own "<name>.*" keys
    try:
        out["r"], out["vals"], out["done"] = screen_on(s, s.base_model, s.th_base, [], nm, None)
    except (FitError, EffectError) as err:
        out["error"] = str(err)
    out["seconds"] = time.perf_counter() - tc
    return out


def _screened(s: Setup, nm: str, results: list[dict]) -> tuple[Candidate, dict | None, tuple | None, dict]:
    """A candidate from its variants' screens: (candidate, effect values or None if every variant failed, the
    joint refit if the screen was one, the variant kept)."""
    score, ev = results[0]["score"], results[0]["ev"]
    tried = [(x["r"], x["var"], x["vals"], x["done"]) for x in results if "error" not in x]
    vals: dict | None = None
    done: tuple | None = None
    var: dict = {}
    runner_up = None
    alike: list = []
    if tried:
        tried.sort(key=lambda x: x[0])
        r, var, vals, done = tried[0]
        # what the best leaves above the floor may hold another effect, which can tip the choice either way
        excess = r * r - (s.noise_margin * s.noise) ** 2
        close = [x for x in tried if np.isfinite(x[0]) and (x[0] < s.min_factor * r or x[0] ** 2 - r * r < excess)]
        alike = [(vv, _values_at(s, vl, dn)) for _, vv, vl, dn in close] if len(close) > 1 else []
        if len(tried) > 1 and done is None and tried[1][3] is None and np.isfinite(tried[1][0]):
            runner_up = (tried[1][2], tried[1][1])
        if len(tried) > 1:
            ev += ("; tried " + " and ".join(f"{variant_label(vv)} ({fmt_len(rv)} on validation)"
                                             for rv, vv, _, _ in tried) + f": kept {variant_label(var)}")
    else:
        r = math.inf
        ev = f"{ev}; the fit failed: {'; '.join(x['error'] for x in results)}"
    base_val = s.base_val
    cand = Candidate(nm, r, math.nan, base_val / r if r > 0 else math.inf, False, score, ev, params=vals or {},
                     runner_up=runner_up, alike=alike)
    s.say(f"screen {s.base}+{nm}: validation RMSE {fmt_len(r)} ({base_val / r:.2f}×), residual test "
          f"{score:.2f}, {sum(x['seconds'] for x in results):.1f} s")
    return cand, vals, done, var


def _values_at(s: Setup, vals: dict, done: tuple | None) -> dict:
    """Base and effect values of a screen: its joint refit's, or the fitted base's and the screened effect's."""
    if done is not None:
        return dict(done[0].unpack(done[1]))
    return {**s.base_model.unpack(s.th_base), **vals}


def refit_all(s: Setup, cands: dict, carry: dict, full: dict) -> list:
    """Stage 2: every candidate refitted jointly with the base from its screened point (never worse than that
    point), then marked significant or not; returns the candidates ranked (significant first, by RMSE).

    Screened with the base held fixed, an effect the base partly imitates (an output nonlinearity its ψ/α
    terms bend towards, a delay its δ terms mimic) can look useless, or even worse than the base, and still
    take the error to the noise floor once refitted with it (the hidden asymmetry bag: 0.95× screened, 27×
    refitted) — so all of them are refitted, not only the best screened.
    """
    val, train = s.val, s.train
    _refit_each(s, cands, carry, full)
    before = s.base_val
    if rebase(s, full) and before >= s.min_factor * s.base_val:  # a smaller move is no new basin
        _rescreen(s, cands, carry, full)
        # The new refits' base parameters are starts too: a base still short of its best would make every
        # effect that lets the base move on look significant (effect-free records then named one).
        rebase(s, full)
    base_val = s.base_val
    for nm, (m, th, e) in full.items():
        c = cands[nm]
        # The refit started from the screened point and kept it if it could not improve on it, so its numbers
        # (and its paired test) stand for the candidate even where the screen's offset differed slightly.
        c.rmse, c.rmse_train = rmse(e[val]), rmse(e[train])
        c.improvement = base_val / c.rmse if c.rmse > 0 else math.inf
        c.t_stat = paired_t(s.e_base[val], e[val])
        c.params = _effect_values(m, th)
        carry[nm] = c.params
    for c in cands.values():
        c.significant = bool(not s.at_floor and c.effect in full and c.improvement >= s.min_factor
                             and c.t_stat >= s.t_min)
    if not any(c.significant for c in cands.values()):
        # none validated: the base's hold-out may miss where one acts (:mod:`.blind`); one at most is marked
        ok, pick, why = training_only(s, [(rmse(e[val]), nm, m, th, e) for nm, (m, th, e) in full.items()],
                                      s.e_base, base_val)
        if ok:
            c = cands[ok[pick][1]]
            c.significant, c.note = True, why
    return sorted(cands.values(), key=lambda c: (not c.significant, c.rmse))


def _refit_each(s: Setup, cands: dict, carry: dict, full: dict) -> None:
    """Refit every screened candidate not yet refitted jointly with the base, from its screened point, in its best
    screened configuration and in its runner-up (the better refit kept, with its configuration).

    With the base held fixed the screens rank an effect's configurations by what they add to a base that has
    already bent towards the effect: two modes in cascade screened worse than one (56.4 against 38.6 nm) on a
    generated stage with two modes (2000147, the generator's earlier form of them), where refitted jointly they
    reached the noise floor and one mode 11.3 nm.
    """
    order = sorted(cands.values(), key=lambda c: c.rmse)
    todo = [c.effect for c in order if c.effect not in full and np.isfinite(c.rmse)]
    items = [(nm, carry.get(nm), None) for nm in todo]
    items += [(nm, *cands[nm].runner_up) for nm in todo if cands[nm].runner_up is not None]
    if isinstance(s.say, _Progress):
        s.say.total += len(items) - len(todo)

    def one(own: Setup, item: tuple):
        nm, vals, var = item
        if var is not None:
            own.cfg.update(var)
        return _refit_one(own, nm, vals, variant_suffix(var or {}))
    for (nm, _, var), res in zip(items, pmap(s, one, items)):
        if res is not None and (nm not in full or _better_config(s, res, full[nm])):
            if nm in full:
                cands[nm].evidence += (f"; refitted jointly with the base, {variant_label(var or {})} was kept "
                                       f"({fmt_len(rmse(res[2][s.val]))} on validation against "
                                       f"{fmt_len(rmse(full[nm][2][s.val]))}, {len(res[1])} parameters against "
                                       f"{len(full[nm][1])})")
            full[nm] = res
            s.cfg.update(own_config(res[0], nm))
    for c in order:
        if c.effect not in full:
            c.evidence += " (screened with the base model held fixed: its joint refit failed)"


def validate_alike(s: Setup, r: float, r_best: float, t: float) -> bool:
    """Two models validate alike: the better (``r_best``) does not beat the other (``r``, paired t ``t`` of its
    squared-error cut) by the standard an effect must meet against the model below it — ``min_factor``× and paired
    t ≥ ``t_min`` (far from the noise floor two models 2 % apart can differ by a large t). The exchange step
    (:mod:`.swap`) and the choice between an effect's configurations (:func:`_refit_each`) judge by it."""
    return t < s.t_min or r < s.min_factor * r_best


def _better_config(s: Setup, new: tuple, old: tuple) -> bool:
    """Whether the joint refit ``new`` (model, θ, residual) of an effect in another configuration replaces
    ``old``: it validates better, unless only alike (:func:`validate_alike`) with more parameters; or it
    validates alike with fewer (one mode where two add nothing the record shows)."""
    r_new, r_old = rmse(new[2][s.val]), rmse(old[2][s.val])
    k_new, k_old = len(new[1]), len(old[1])
    if r_new < r_old:
        return k_new <= k_old or not validate_alike(s, r_old, r_new, paired_t(old[2][s.val], new[2][s.val]))
    return k_new < k_old and validate_alike(s, r_new, r_old, paired_t(new[2][s.val], old[2][s.val]))


def _refit_one(s: Setup, nm: str, vals: dict | None, label: str = "") -> tuple | None:
    """Effect ``nm`` refitted jointly with the base from its screened values: (model, θ, residual) or None."""
    t, u, y, val = s.t, s.u, s.y, s.val
    try:
        m, th, yh = guarded_refit(s.base_model, [nm], s.cfg, t, u, y, val,
                                  {**s.base_model.unpack(s.th_base), **(vals or {})},
                                  theta_base=s.th_base, fitter=s.fit, prior=vals)
    except (FitError, EffectError):
        return None
    s.say(f"refit {m.name}{label}: validation RMSE {fmt_len(rmse((y - yh)[val]))}")
    return m, th, y - yh


def _rescreen(s: Setup, cands: dict, carry: dict, full: dict) -> None:
    """After :func:`rebase` moved the base to a better basin: screen and refit every candidate again from it.

    The first round started from the poor base; a candidate refitted from there can end worse than the new
    base alone while the same effect on top of the new base explains the error (generated drift + two modes on
    steps: the base fit 6.67 µm, + delay 208 nm, the base refitted from there 104 nm — and every candidate then
    looked worse than the base: "unexplained" at 80× the noise). Each candidate keeps the better of its two
    joint refits (identification never goes backwards), with the configuration that refit used, and its residual
    signature is taken again on the new base's residual.
    """
    val = s.val
    if isinstance(s.say, _Progress):
        s.say.total += 2 * len(s.names)
    again, again_carry, again_full = screen_all(s)
    _refit_each(s, again, again_carry, again_full)
    for nm, c in again.items():
        new, old = again_full.get(nm), full.get(nm)
        cands[nm].score, cands[nm].evidence, cands[nm].alike = c.score, c.evidence, c.alike
        if new is not None and (old is None or rmse(new[2][val]) < rmse(old[2][val])):
            full[nm], carry[nm] = new, again_carry.get(nm, {})
        elif old is not None:  # the first round's refit stays: so does the configuration it was fitted in
            s.cfg.update(own_config(old[0], nm))


#: The base is refitted from the base parameters of at most this many of the best joint refits (:func:`rebase`).
REBASE_STARTS = 3


def rebase(s: Setup, full: dict) -> bool:
    """Refit the base alone from the base parameters of the best joint refits; keep a better base.

    The base fit can end in a poor basin (on generated records without any effect, 4 of 32 ended 4–17× the noise),
    and then any effect that lets the joint fit leave that basin looks significant — a false alarm. A joint
    refit's base parameters are a start the base fit never tried: if the base alone, refitted from there,
    validates better, the base was the problem, and every candidate is judged against the better base (the
    residual the later stages read is the new base's). Identification never goes backwards: the base kept is the
    best found. Effects that replace the base recursion (kind ``base``) carry no base parameters to start from.
    Returns whether the base was replaced.
    """
    t, u, y, val = s.t, s.u, s.y, s.val
    best_val = s.base_val
    if best_val <= s.noise_margin * s.noise:
        return False
    starts = sorted(((rmse(e[val]), nm, m, th) for nm, (m, th, e) in full.items()
                     if not any(getattr(ef, "kind", "") == "base" for ef in getattr(m, "effects", ()))),
                    key=lambda x: x[0])[:REBASE_STARTS]
    found = None
    for r_c, nm, m, th in starts:
        if not best_val / r_c >= s.min_factor:  # a candidate that would not be significant cannot mislead
            continue
        try:
            th_b = s.fit(s.base_model, t, u, y, cast(ComposedModel, m).split(th)[0])
            e_b = y - _simulate(s.base_model, th_b, t, u)
        except FitError:
            continue
        if rmse(e_b[val]) < best_val:
            best_val, found = rmse(e_b[val]), (nm, th_b, e_b)
    if found is not None:
        nm, s.th_base, s.e_base = found
        s.say(f"base {s.base} refitted from the base parameters of +{nm}: validation RMSE {fmt_len(best_val)}",
              step=False)
    return found is not None
