"""Does the record determine the base model? A caution when the base does not carry over to its own hold-out.

Every candidate effect is judged by how much it improves the base model's error on the held-out blocks. That
judgement assumes the base itself carries over from the training samples to the held-out ones, as a model of the
stage should. When the base errs far more on the held-out samples than on those it was fitted to, the record does
not determine it — a few steps at levels the training part never visited, a short record — and an effect that
"improves" the hold-out may only be helping the base extrapolate. Generated GMA stage 1600045 (no effect at all,
4 s at 5 kHz, five steps): the base fitted its training part to 1.5× the noise floor and the held-out part to
13.1×, and creep was named; on a fresh record of the same stage the creep model was worse than the base.

The caution changes no answer; it says how far to trust it and what to check. It is not specific: on the
benchmark's own family (seed 17, 200 records) it was raised on 20, 18 of them answered right — an effect that
shows mostly in the held-out blocks (a hard stop reached there, a mode rung by the steps there) looks the same.
"""
from __future__ import annotations

import numpy as np

from ..effects.signals import fmt_len

__all__ = ["GENERALISATION_FACTOR", "base_caution"]

#: The base model errs this many times more on the held-out samples than on its training samples (RMSE ratio):
#: it does not carry over within the record.
GENERALISATION_FACTOR = 3.0


def base_caution(base: str, val_rmse: float, train_rmse: float, noise: float, u: np.ndarray,
                 floor_factor: float) -> str | None:
    """The caution for a base model with validation RMSE ``val_rmse`` and training RMSE ``train_rmse`` (m), or
    None when it carries over (or its held-out error is within ``floor_factor`` × the noise floor ``noise``).

    ``u`` (V) only enters the message: for a steps record (mostly holds), how many input changes it holds.
    """
    if not (np.isfinite(val_rmse) and np.isfinite(train_rmse)) or val_rmse < floor_factor * noise:
        return None
    ratio = val_rmse / max(train_rmse, noise, 1e-300)
    if ratio < GENERALISATION_FACTOR:
        return None
    du = np.abs(np.diff(np.asarray(u, dtype=np.float64)))
    moving = float(np.mean(du > 0)) if du.size else 0.0
    hint = ""
    if du.size and moving < 0.25:  # mostly holds: a steps record; count its steps
        steps = int(np.count_nonzero(du > 1e-3 * (np.ptp(u) or 1.0)))
        hint = f" (the record holds {steps} input changes)"
    return (f"caution: the {base} model errs {ratio:.1f}× more on the held-out samples ({fmt_len(val_rmse)}) than "
            f"on those it was fitted to ({fmt_len(train_rmse)}): either an effect shows mostly there, or this record "
            f"does not determine the base{hint} and an effect may only be helping it extrapolate — check the answer "
            "on a fresh record (hyst compare DATA2 --params P) or record a longer or richer excitation (more steps, "
            "or sines or noise across the range)")
