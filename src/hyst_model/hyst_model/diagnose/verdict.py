"""Stage 4 of :func:`hyst_model.diagnose.diagnose.diagnose`: the answer — the ranking (:func:`final_order`), the
missing effect, an unexplained remainder and the explanation in words (:func:`verdict`)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..effects.signals import fmt_len
from ..model import Model
from .refit import _simulate
from .setup import Setup
from .unexplained import Unexplained, explain_unexplained

__all__ = ["final_order", "verdict"]


def final_order(chosen: list, cands: dict) -> list:
    """The final model's effects, best first: the ladder's first (what explains most of the error on its own),
    then the others by what each adds to the final model — the validation RMSE without it, worst first.

    The ladder adds effects greedily, so after the first its order follows the path: an effect taken on a rung
    can stand in for part of one taken later, which then explains more (generated GMA stage 3800163, creep with
    two modes: creep, then a delay imitating the modes' phase, then the modes; without the delay the final model
    validates at 2.62 nm against 2.61 nm, without the modes at 4.37 nm — the modes are what the record needs
    second). The backward step's last round measured exactly that (:attr:`~.setup.Candidate.rmse_without`); where it did
    not run on every one of them, the ladder's order stands."""
    rest = list(chosen[1:])
    if len(rest) < 2 or any(cands[nm].rmse_without is None for nm in rest):
        return list(chosen)
    return [chosen[0]] + sorted(rest, key=lambda nm: -float(cands[nm].rmse_without))


def verdict(s: Setup, cands: dict, ladder: list, models: dict[str, tuple[Model, np.ndarray]], chosen: list,
            unexplained_factor: float, explain: Callable) -> tuple[list, str, Unexplained | None, str]:
    """Stage 4: the answer — candidates best first, the missing effect (``none``/``unexplained`` included),
    the description of an unexplained remainder, and the explanation in words.

    ``explain(candidate, base, rmse_it_improves_on)`` writes each candidate's evidence sentence.
    """
    base, noise, base_val = s.base, s.noise, s.base_val
    # Best first: the final model's effects, then the rest by validation RMSE.
    ranked = [cands[nm] for nm in final_order(chosen, cands)] + sorted(
        (c for c in cands.values() if c.effect not in chosen), key=lambda c: (not c.significant, c.rmse))
    # A candidate was tried on the climb's rung with its effects: the first such rung (the after-the-ladder steps
    # append rungs with the same effects, refitted, which it was not tried on)
    rung_val: dict[tuple, float] = {}
    for rg in ladder:
        rung_val.setdefault(tuple(rg.effects), rg.rmse)
    for c in ranked:
        c.evidence = explain(c, base, rung_val.get(tuple(c.on_top_of), base_val))
        if c.note:
            c.evidence += f"; {c.note}"
        if c.rmse_without is not None and c.effect in chosen:
            c.evidence += f"; without it the final model validates at {fmt_len(c.rmse_without)}"
    missing = chosen[0] if chosen else "none"
    left = ladder[-1].rmse
    unexplained = None
    if left >= unexplained_factor * noise:
        m_last, th_last = models[ladder[-1].model]
        y_last = _simulate(m_last, th_last, s.t, s.u)
        # Learn the loop-shape functions on the first half of the held-out samples, test them on the second: both
        # halves are out of sample for the model (its training residual is fitted away and says little).
        vi = np.flatnonzero(s.val)
        first = np.zeros(vi.size, dtype=bool)
        first[: vi.size // 2] = True
        unexplained = explain_unexplained(s.u, s.y - y_last, y_last, vi, first, left, noise, base,
                                          [nm for nm in s.names if nm not in chosen])
        if not chosen:
            missing = "unexplained"
    if s.at_floor and not chosen:
        expl = (f"the {base} model already predicts held-out data to {fmt_len(base_val)} RMS, at the sensor "
                f"noise floor ({fmt_len(noise)}): no effect is missing")
    elif not chosen:
        expl = (f"the {base} model leaves {fmt_len(base_val)} RMS (noise floor {fmt_len(noise)}), but no candidate "
                f"predicts held-out data significantly better (needs ≥ {s.min_factor:g}× and paired t ≥ "
                f"{s.t_min:g}); the remaining error is none of: {', '.join(s.names)}")
        if unexplained is not None:
            expl = f"unexplained ({unexplained.kind}): {unexplained.evidence}"
    else:
        expl = " → ".join(f"{r.model} {fmt_len(r.rmse)}" for r in ladder)
        expl += (" (at the noise floor)" if left <= s.noise_margin * noise else
                 f" (still {left / noise:.1f}× the noise floor: something else is missing too)")
        if unexplained is not None:
            expl += f"; what is left is {unexplained.kind}: {unexplained.evidence}"
    return ranked, missing, unexplained, expl
