"""Stage 3 of :func:`hyst_model.diagnose.diagnose.diagnose`: the error ladder (:func:`climb`) and how it chooses
between candidates that validate alike (:func:`prefer_simpler`)."""
from __future__ import annotations

from typing import cast

import numpy as np

from ..effects import compose
from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from ..errors import EffectError, FitError
from ..model import Model
from .alike import alike_refits, simpler_alike
from .blind import beaten_in_training, training_only
from .parallel import pmap
from .refit import _effect_values, guarded_refit, paired_t, refit, rmse
from .setup import Candidate, Rung, Setup
from .stages import (_better_config, effect_order, effect_variants, n_params, own_config, screen_on, variant_label,
                     variant_suffix)

__all__ = ["climb", "prefer_simpler", "training_only", "n_params", "effect_order", "STRONG_SIGNATURE",
           "SIGNATURE_MARGIN", "OTHER_ORDER_TOP"]


#: A residual signature at least this strong earns a candidate a joint refit at a rung even when its screen does not.
STRONG_SIGNATURE = 0.5

#: A residual signature this much stronger than the taken effect's is reported as disagreeing with the choice.
SIGNATURE_MARGIN = 0.2


def prefer_simpler(s: Setup, options: list[tuple[str, float, np.ndarray, float]]) -> tuple[int, str]:
    """Index of the option to take from ``(effect, validation RMSE, residual, signature score)``, and why.

    The best by validation RMSE, unless others are as good — the best does not cut their squared error
    significantly (paired t below ``t_min``; with ``min_factor`` too, as :func:`~.stages.validate_alike` has it,
    four of 200 generated cases lost their name: a soft saturation 5 % better than a quadratic bow, a two-mode
    resonance than a delay). Among those the record cannot tell them apart, so parsimony decides: the
    fewest free parameters (a parameter must earn its place, as it must against the base — a 3-parameter mode
    imitates a sub-sample delay, and a slow one with 1 % participation imitates creep, as well as the effect
    itself does), then the lower RMSE. The residual signatures only corroborate: when
    the taken effect's is clearly weaker (by more than :data:`SIGNATURE_MARGIN`) than the best one's, the evidence
    says they disagree. (Deciding by the signatures instead named a 0.3-sample sensor delay a 370 Hz, ζ 0.76
    "mode" on generated records: a linear-interpolated delay has an acceleration-shaped residual too.)
    """
    best = min(range(len(options)), key=lambda i: options[i][1])
    nm_b, r_b, e_b, sc_b = options[best]
    alike = [(best, 0.0)]
    for i, (nm, r, e, _) in enumerate(options):
        if i != best:
            t = paired_t(e[s.val], e_b[s.val])
            if t < s.t_min:
                alike.append((i, t))
    if len(alike) == 1:
        return best, ""
    beaten = beaten_in_training(s, options, [i for i, _ in alike])
    ks: dict[int, int] = {}
    for i, _ in alike:
        k_i = n_params(s, options[i][0])
        if k_i is None:  # every option was fitted, so each composes; never counted as parameter-free
            raise EffectError(f"{options[i][0]} does not compose on {s.base} in the configuration it was fitted in")
        ks[i] = k_i
    k, r, pick, t = min((ks[i], options[i][1], i, t) for i, t in alike if i not in beaten)
    if pick == best:
        return best, ""
    sc = options[pick][3]
    if best in beaten:
        why = (f"taken before {nm_b} ({fmt_len(r_b)} on validation): they validate alike (paired t {t:.1f} < "
               f"{s.t_min:g}), but the validation blocks do not reach where they differ — on the training part "
               f"{nm_b} leaves {fmt_len(rmse(e_b[s.train]))} and it {fmt_len(rmse(options[pick][2][s.train]))}")
        return pick, why
    why = (f"taken before {nm_b} ({fmt_len(r_b)} on validation, {ks[best]} parameters): they validate "
           f"alike (paired t {t:.1f} < {s.t_min:g}) and it has fewer parameters ({k})")
    if sc_b > sc + SIGNATURE_MARGIN:
        why += (f"; the residual signatures disagree ({nm_b} {sc_b:.2f}, {options[pick][0]} {sc:.2f}): the record "
                "cannot tell the two apart")
    return pick, why


def climb(s: Setup, ranked: list, cands: dict, carry: dict, full: dict, pair: tuple | None = None
          ) -> tuple[list, dict[str, tuple[Model, np.ndarray]], list]:
    """Stage 3: the error ladder — the best significant effect, then, while the error is above the noise floor,
    the best further effect screened on top of the current rung and refitted (``full_rate_top`` of them).

    ``pair``: where no single effect is significant, two that are only together (:func:`~.jointly.joint_pair`:
    ``(validation RMSE, (first, second), model, θ, residual)``) make the first rung instead.

    Returns ``(ladder, models, chosen)``: the rungs, (model, θ) by model name, the effects in order.
    """
    t, u, y, val, train = s.t, s.u, s.y, s.val, s.train
    ladder = [Rung(s.base, [], s.base_val, rmse(s.e_base[train]))]
    models: dict[str, tuple[Model, np.ndarray]] = {s.base: (s.base_model, s.th_base)}
    chosen: list[str] = []
    if ranked and ranked[0].significant:
        sig = [c for c in ranked if c.significant and c.effect in full]
        pick, why = prefer_simpler(s, [(c.effect, c.rmse, full[c.effect][2], c.score) for c in sig])
        best = sig[pick]
        best.note = why or best.note  # a candidate taken on the training part's evidence keeps saying so
        m, th, e = full[best.effect]
        chosen.append(best.effect)
        ladder.append(Rung(m.name, list(chosen), best.rmse, best.rmse_train))
    elif pair is not None:
        r, names, m, th, e = pair
        for i, nm in enumerate(names):  # the second stands on the first (what the pair's rung shows)
            _on_top(s, cands[nm], list(names[:i]), s.e_base, s.base_val, (r, nm, m, th, e), significant=True)
        chosen.extend(names)
        ladder.append(Rung(m.name, effect_order(m), r, rmse(e[train])))
    else:
        return ladder, models, chosen
    models[m.name] = (m, th)
    cur_e = e
    while len(chosen) < s.max_rungs:
        cur_val = rmse(cur_e[val])
        if cur_val <= s.noise_margin * s.noise and not rmse(cur_e[train]) >= s.min_factor * max(cur_val, s.noise):
            break  # at the floor on validation, and training shows nothing more (:func:`training_only`)
        # A second effect is often masked by the first when tested alone: screen every remaining one on top of
        # the current rung, then refit the best at full rate.
        prev_m, prev_th = models[ladder[-1].model]
        prev_c = cast(ComposedModel, prev_m)  # every rung above the base is a refitted composed model
        order = effect_order(prev_m)  # the rung's effects as its model applies them (innermost first)
        screened: dict = {}  # effect -> (model, θ, residual) of a screen that was itself a joint refit

        # Every configuration of every candidate is screened again on top of the rung: the one kept on the bare
        # base was judged with the rung's effect still in the residual (a 6-sample delay: asymmetry kept as a
        # gain kink, 30 nm on top of the delay, where the stage's quadratic bow reached the noise floor).
        def screen(own: Setup, item: tuple[str, dict]):
            nm, var = item
            own.cfg.update(var)
            try:
                compose(own.base_model, order + [nm], own.cfg)
                r_s, vals, full_s = screen_on(own, prev_m, prev_th, order, nm, carry.get(nm))
            except (EffectError, FitError):
                return None
            own.say(f"screen {prev_m.name}+{nm}{variant_suffix(var)}: validation RMSE {fmt_len(r_s)}", step=False)
            return r_s, nm, vals, full_s, var

        best_s: dict[str, tuple] = {}
        all_s: dict[str, list] = {}
        items = [(nm, v) for nm in s.names if nm not in chosen for v in _rung_variants(s, nm)]
        for res in pmap(s, screen, items):
            if res is not None:
                all_s.setdefault(res[1], []).append(res)
                if res[1] not in best_s or res[0] < best_s[res[1]][0]:
                    best_s[res[1]] = res
        trial_s = []
        for r_s, nm, vals, full_s, var in best_s.values():
            simpler = simpler_alike(s, all_s[nm], best_s[nm]) if full_s is None else []
            trial_s.append((r_s, nm, vals, var, simpler))
            if full_s is not None:
                screened[nm] = full_s
        trial_s.sort(key=lambda x: x[0])
        # The screen holds the rung fixed and can undersell an effect only a joint refit shows (creep on top of
        # a delay: 63 nm screened, 2 nm refitted): the strongest residual signature beyond the top screened ones
        # is refitted too, when it is strong.
        top = trial_s[:s.full_rate_top]
        strong = [x for x in trial_s[s.full_rate_top:] if cands[x[1]].score >= STRONG_SIGNATURE]
        if strong:
            top.append(max(strong, key=lambda x: cands[x[1]].score))

        def refit_on(own: Setup, item: tuple):
            r_s, nm, vals, var, simpler = item
            cfg0 = dict(own.cfg)
            out = refit_in(own, nm, vals, var, True)
            # a configuration with fewer parameters that screened alike is refitted too (:func:`~.alike.simpler_alike`)
            for vals2, var2 in simpler:
                own.cfg.clear()
                own.cfg.update(cfg0)
                alt = refit_in(own, nm, vals2, var2, False)
                if alt is not None and (out is None or _better_config(s, alt[2:], out[2:])):
                    out = alt  # the simpler, unless the richer validates better by the standard (as on the base)
            return out

        def refit_in(own: Setup, nm: str, vals: dict, var: dict, with_screen: bool):
            own.cfg.update(var)
            options = []  # (model, θ, residual)
            rung_vals = _effect_values(prev_m, prev_th)
            for start, kept in _value_starts(own, order, nm, vals, carry.get(nm), nm in screened):
                try:
                    # the screen's values only where the effect's own data start gives none (``prior``); its own
                    # values from the base over that start (``carry``)
                    mm, tth, yh = guarded_refit(own.base_model, order + [nm], own.cfg, t, u, y, val,
                                                {**prev_m.unpack(prev_th), **start},
                                                theta_base=prev_c.split(prev_th)[0],
                                                carry={**rung_vals, **start} if kept else rung_vals,
                                                prior=None if kept else start, fitter=own.fit)
                    options.append((mm, tth, y - yh))
                except (EffectError, FitError):
                    pass
            # A screen that refitted jointly from the base (delay, asymmetry) may have found a better basin than
            # the refit carrying this rung's values: never go back from a model already found (a creep rung with
            # an overdamped 21 Hz "mode" refitted to 39.7 nm, while the screen from the base had reached 2.15 nm).
            if with_screen and nm in screened:
                options.append(screened[nm])
            if not options:
                return None
            mm, tth, e = min(options, key=lambda o: rmse(o[2][val]))  # the refit on a tie
            own.say(f"refit {mm.name}{variant_suffix(var)}: validation RMSE {fmt_len(rmse(e[val]))}")
            return rmse(e[val]), nm, mm, tth, e

        trial = [x for x in pmap(s, refit_on, [x for x in top if np.isfinite(x[0])]) if x is not None]
        if not trial:
            break
        _other_order(s, trial, prev_m, cur_val)
        _fresh_start(s, trial, cur_val)
        # and with a carried effect in a configuration the base could not tell from the one kept (:mod:`.alike`)
        _retry_best(s, trial, cur_val, lambda own, i: alike_refits(own, trial[i], cands), ALIKE_TOP)
        good = [x for x in trial if cur_val / x[0] >= s.min_factor and paired_t(cur_e[val], x[4][val]) >= s.t_min]
        pick, why = prefer_simpler(s, [(x[1], x[0], x[4], cands[x[1]].score) for x in good]) if good else (-1, "")
        if not good:  # none validated: one the hold-out cannot see may still be needed where training looks
            good, pick, why = training_only(s, trial, cur_e, cur_val)
        # Every candidate refitted on top of this rung now stands for what it adds to it (the ranking of those
        # the ladder does not take is by that, not by what each did alone on the base).
        for x in trial:
            if not good or x is not good[pick]:
                _on_top(s, cands[x[1]], chosen, cur_e, cur_val, x, significant=False)
        if not good:
            break
        r, nm, mm, tth, e = good[pick]
        for x in effect_order(mm):  # the configurations it was taken in (a carried effect's may have changed:
            now = own_config(mm, x)  # .alike), for the rungs and the prune after
            if x != nm and x in cands and any(s.cfg.get(k) != v for k, v in now.items()):
                cands[x].note = _join(cands[x].note, f"with {nm} on top it was refitted in {variant_label(now)} "
                                      "(on the base alone the choice between the two was not settled)")
            s.cfg.update(now)
        c = cands[nm]
        c.note = why
        _on_top(s, c, chosen, cur_e, cur_val, good[pick], significant=True)
        chosen.append(nm)
        ladder.append(Rung(mm.name, effect_order(mm), r, rmse(e[train])))
        models[mm.name] = (mm, tth)
        cur_e = e
    return ladder, models, chosen


def _join(a: str, b: str) -> str:
    return f"{a}; {b}" if a else b


def _rung_variants(s: Setup, nm: str) -> list[dict]:
    """The configurations of ``nm`` screened on a rung: the one in force, and the others except those that
    replace the base recursion (kind ``base``: the feedback structure of dynamics) — their screen is a joint refit
    of the whole rung (8.6 s of a 42 s diagnosis of 60k samples) and they were judged against the base already —
    and those with more parameters than the one in force (dynamics' second mode): they were refitted jointly
    against the base, which a screen on the rung held fixed cannot judge (it preferred two modes on top of creep
    where one refitted 25 % better), and each rung model with them costs 4x the fit time."""
    out = []
    k_now = n_params(s, nm)
    for v in effect_variants(s, nm):
        if v and not all(s.cfg.get(k) == x for k, x in v.items()):
            try:
                e = compose(s.base_model, [nm], {**s.cfg, **v}).effects[-1]
            except EffectError:
                continue
            if getattr(e, "kind", "") == "base" or (k_now is not None and len(e.params()) > k_now):
                continue
        out.append(v)
    return out or [{}]


def _value_starts(s: Setup, order: list, nm: str, screened: dict, own: dict | None, refitted: bool
                  ) -> list[tuple[dict, bool]]:
    """Effect values a rung's refit of ``nm`` starts from, each with whether it overrides the effect's own data start:
    its screen's on the rung (it does not), and — for an effect screened with the rung held fixed — its own values
    from its joint refit with the base alone (``own``; it does), when they belong to the configuration screened and
    differ.

    A screen with the rung held fixed can move an effect away from where it stands with the base free: on generated
    GMA stage 3000163 (two-lag creep and two modes) the mode's values refitted with the base alone (13.8 nm)
    screened on the creep rung at 34.9 nm, the refit from that screen ended at 14.6 nm (4.1× the noise floor),
    while the creep rung refitted with the mode's own values reaches 1.33× the floor. An effect whose screen was
    itself a joint refit from those values (``refitted``) has been tried from them already.
    """
    starts = [(screened, False)]
    if refitted or not own or own == screened:
        return starts
    try:
        names = set(compose(s.base_model, order + [nm], s.cfg).names)
    except EffectError:
        return starts
    if all(k in names for k in own):
        starts.append((own, True))
    return starts


#: How many of a rung's best refits are also tried with the new effect innermost (:func:`_other_order`).
OTHER_ORDER_TOP = 2

#: The best refits of a rung tried with a carried effect in another configuration (:func:`~.alike.alike_refits`).
ALIKE_TOP = 3


def _other_order(s: Setup, trial: list, prev_m: Model, cur_val: float) -> None:
    """Try the best :data:`OTHER_ORDER_TOP` refits of a rung with the new effect innermost, keeping the better order;
    only refits that improve on the rung's validation RMSE ``cur_val`` at all.

    The ladder adds each effect outside the rung's, but effects that do not commute — a nonlinear map and a
    dynamic one (the stage's bow before its creep, a saturation before a mode) — are not the same model in the
    other order, and the record may say which: the generated sim stage with asymmetry inside creep, fitted as
    creep then asymmetry outside it, left 20 nm (8x its noise floor). Linear effects commute (nothing to try).
    Entries of ``trial`` (validation RMSE, name, model, θ, residual) are replaced in place.
    """
    t, u, y, val = s.t, s.u, s.y, s.val
    order = effect_order(prev_m)
    if not order:
        return

    def other(own: Setup, i: int):
        r, nm, mm, tth, e = trial[i]
        own.cfg.update(own_config(mm, nm))
        try:
            m2 = compose(own.base_model, [nm] + order, own.cfg)
        except EffectError:
            return None
        if all(getattr(x, "linear", False) for x in m2.effects):
            return None
        try:
            # from the refit's own point, the effect moved inward
            mc = cast(ComposedModel, mm)
            m2, th2, yh2 = guarded_refit(own.base_model, [nm] + order, own.cfg, t, u, y, val, mc.unpack(tth),
                                         theta_base=mc.split(tth)[0], carry=_effect_values(mm, tth),
                                         fitter=own.fit)
        except (EffectError, FitError):
            return None
        r2 = rmse((y - yh2)[val])
        own.say(f"refit {m2.name}: validation RMSE {fmt_len(r2)}")
        if not r2 < trial[i][0]:
            return m2, th2, y - yh2
        # The other order found a better basin: the first order once more from there, as its values are often
        # close to that order's too (generated GMA stage 208, a 463 Hz mode behind a limit losing 0.19 of the
        # stroke at each end: limit then mode, the stage's order, refitted from the rung 60.1 nm; the mode inside
        # the limit 9.21 nm; from that fit's values the stage's order reaches the noise floor, 2.07 nm).
        try:
            m3, th3, yh3 = guarded_refit(own.base_model, order + [nm], own.cfg, t, u, y, val, m2.unpack(th2),
                                         theta_base=m2.split(th2)[0], carry=_effect_values(m2, th2),
                                         fitter=own.fit)
        except (EffectError, FitError):
            return m2, th2, y - yh2
        r3 = rmse((y - yh3)[val])
        own.say(f"refit {m3.name} from {m2.name}: validation RMSE {fmt_len(r3)}")
        return (m3, th3, y - yh3) if r3 < r2 else (m2, th2, y - yh2)

    # Any refit that improves on the rung, not only those it could take already: the other order can be what
    # makes an effect significant (generated creep + a slow trend: creep outside drift 1.34 nm, not enough against
    # 1.47 nm; inside it 1.17 nm, and creep was named).
    _retry_best(s, trial, cur_val, other)


def _fresh_start(s: Setup, trial: list, cur_val: float) -> None:
    """Refit the best :data:`OTHER_ORDER_TOP` models of a rung once more from the bare base, every effect from its
    own data-driven start, keeping whichever validates better (in place, as :func:`_other_order`).

    A rung's refits start from the rung below, and a basin found there is inherited: generated stage 1009 (slow
    periodic drift + a 391 Hz mode), creep first, then on top of it an overdamped 20 Hz "mode", then drift — 29.5
    nm (12x the noise floor) where drift + dynamics from their own starts reach 7.5 nm with the mode at 390 Hz.
    """
    t, u, y, val = s.t, s.u, s.y, s.val

    def fresh(own: Setup, i: int):
        mm = trial[i][2]
        names = effect_order(mm)
        for nm in names:
            own.cfg.update(own_config(mm, nm))
        try:
            m2, th2, yh2 = refit(own.base_model, names, own.cfg, t, u, y, s.th_base, fitter=own.fit)
        except (EffectError, FitError):
            return None
        own.say(f"refit {m2.name} from the base: validation RMSE {fmt_len(rmse((y - yh2)[val]))}")
        return m2, th2, y - yh2

    _retry_best(s, trial, cur_val, fresh)


def _retry_best(s: Setup, trial: list, cur_val: float, again, top: int = OTHER_ORDER_TOP) -> None:
    """Fit the :data:`OTHER_ORDER_TOP` best entries of ``trial`` that improve on the rung (validation RMSE below
    ``cur_val``) once more with ``again(own, index) -> (model, θ, residual) | None``, side by side; an entry is
    replaced where the new fit validates better (never worse)."""
    val = s.val
    best = [k for k in sorted(range(len(trial)), key=lambda k: trial[k][0])[:top]
            if trial[k][0] < cur_val]
    for i, res in zip(best, pmap(s, again, best)):
        if res is not None and rmse(res[2][val]) < trial[i][0]:
            trial[i] = (rmse(res[2][val]), trial[i][1], *res)


def _on_top(s: Setup, c: Candidate, chosen: list, cur_e: np.ndarray, cur_val: float, trial: tuple,
            significant: bool) -> None:
    """Record on ``c`` what its refit on top of the rung ``chosen`` gave: (rmse, name, model, θ, residual)."""
    r, nm, mm, tth, e = trial
    c.on_top_of, c.rmse, c.rmse_train = list(chosen), r, rmse(e[s.train])
    c.improvement, c.t_stat, c.significant = cur_val / r, paired_t(cur_e[s.val], e[s.val]), significant
    c.params = _effect_values(mm, tth, nm)
