"""Evidence the hold-out cannot give: a rung (or the base) whose validation blocks miss where an effect acts.

The validation blocks of :func:`~.refit.validation_mask` sample every part of the excitation in time, but not
every amplitude or every corner of it. Where an effect acts only there, no refit validates better, while the
training error — on the samples the model was fitted to, which a fitted model matches at least as well as held-out
ones — stays above the validation error. :func:`training_only` then applies the validation test to the training
part. The backward step asks the training part the same way (:func:`~.prune._needed_in_training`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..effects.signals import fmt_len
from .refit import paired_t, rmse

if TYPE_CHECKING:  # stages calls this module on the base's refits
    from .setup import Setup

__all__ = ["training_only", "helps", "beaten_in_training"]


def training_only(s: "Setup", trial: list, cur_e: np.ndarray, cur_val: float) -> tuple[list, int, str]:
    """The refits ``trial`` (validation RMSE, name, model, θ, residual) on top of a rung — or the base — with
    residual ``cur_e`` that only the training part can judge: ``(those, index of the one to take, why)``, or
    ``([], -1, "")``.

    The validation blocks sample every part of the excitation, but not every amplitude or every corner of it:
    where an effect acts only there (a mode rung by the largest triangles' corners, a limit only the largest
    excursion reaches), no refit validates better, while the rung's training error stays far above the floor
    (generated GMA stage 3300139, warm-up drift and a 0.6 % mode: the drift rung validates at 1.26× the noise
    floor and trains at 20×; the fresh record, with the large triangles, was 18.7× the floor, the true effects
    give 1.7×). Such a rung shows it: its training error — on the samples it was fitted to, which a fitted
    model matches at least as well as held-out ones — exceeds its validation error by ``min_factor``. A refit
    is then taken on the training part's evidence by the test validation would apply (``min_factor`` and the
    paired t, :func:`~.prune._needed_in_training` keeps it the same way), if it is no worse on validation — or
    still within ``noise_margin`` of the noise floor there, where validation cannot tell models apart (3400173, a
    two-mode resonance on a delay rung: training 15.5 → 8.2 nm, validation 3.96 → 4.00 nm with the floor at
    3.88 nm); of several, the best on training."""
    tr = s.train
    cur_tr = rmse(cur_e[tr])
    if not (cur_val > 0 and cur_tr / cur_val >= s.min_factor):
        return [], -1, ""
    # A function of time alone (drift) is sampled by the interleaved blocks wherever it acts but before the first
    # one: only there is training's word on it its own (generated GMA stage 3400195: a drift trained 1.13× better
    # on top of creep in the lags form — the form's misfit taken as a function of time — and the fresh record went
    # from 1.7× to 4.8× the floor; a warm-up over by the first block, 3400016, is still seen).
    early = tr & (np.arange(tr.size) < int(np.argmax(s.val)))
    ceiling = max(cur_val, s.noise_margin * s.noise)  # at the floor validation cannot tell refits apart
    ok = [x for x in trial if x[0] <= ceiling and helps(s, early if _of_time(x[1]) else tr, cur_e, x[4])]
    if not ok:
        return [], -1, ""
    pick = min(range(len(ok)), key=lambda i: rmse(ok[i][4][tr]))
    r_tr = rmse(ok[pick][4][tr])
    why = (f"taken on the training part's evidence: the validation blocks do not reach where it acts (the model "
           f"below validates at {fmt_len(cur_val)}, {cur_val / s.noise:.2g}× the noise floor, but trains at "
           f"{fmt_len(cur_tr)}); with it training falls to {fmt_len(r_tr)} (paired t "
           f"{paired_t(cur_e[tr], ok[pick][4][tr]):.1f}) and validation does not rise ({fmt_len(ok[pick][0])})")
    return ok, pick, why


def helps(s: "Setup", part: np.ndarray, cur_e: np.ndarray, e: np.ndarray) -> bool:
    """Whether residual ``e`` beats ``cur_e`` by the validation test (``min_factor`` and the paired t) on the
    samples ``part``."""
    r = rmse(e[part])
    return bool(part.any() and r > 0 and rmse(cur_e[part]) / r >= s.min_factor
                and paired_t(cur_e[part], e[part]) >= s.t_min)


def _of_time(nm: str) -> bool:
    from ..effects import EFFECTS  # late: the effects import the models the diagnosis fits
    return bool(getattr(EFFECTS.get(nm), "of_time", False))


def beaten_in_training(s: Setup, options: list, idx: list[int]) -> set[int]:
    """Those of the options ``idx`` (which validate alike) that the training part rules out: each trains worse
    than it validates by ``min_factor`` — the validation blocks miss where it falls short (:func:`training_only`) — and
    another of them beats it there by the validation test (:func:`helps`). Never all of them: the one
    that trains best is beaten by none.

    Generated GMA stage 3400173 (a two-mode resonance at 3.6× the noise, steps and sines): the mode and a delay
    validate alike at the noise floor, the steps' ringing lies in the training part only (delay 15.5 nm there,
    the mode about half), and parsimony alone took the delay.
    """
    tr, val = s.train, s.val
    out = set()
    for i in idx:
        e = options[i][2]
        if rmse(e[tr]) >= s.min_factor * rmse(e[val]) and any(
                helps(s, tr, e, options[j][2]) for j in idx if j != i):
            out.add(i)
    return out
