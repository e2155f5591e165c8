"""Parameters the record never exercised, moved to where they do not act (:func:`settle`).

A fit leaves a parameter that no sample of the record reaches wherever its gradient vanished: a two-sided
saturation's lower stop just below the lowest output the record shows, when the stage has no lower stop at all
(generated GMA stage 6400182, a hard stop at the top only: the fitted lower asymptote sat 0.4 µm below the
record's lowest output). On the record nothing depends on it; on any wider excursion the model clips at a stop the
record never showed, and a controller holds references there as unreachable (the fresh record of that stage: 1.57 µm
RMSE against 14.8 nm for the base alone, 2.5 nm with the stop moved out). An effect that can tell such parameters
from its own inner output implements ``settle(theta, x)`` and returns parameters that give the *same output on
the record*, bit for bit, with the unreached ones out of the way; :func:`settle` applies it to every effect of a
composed model.
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..model import Model
from .base import ComposedModel

__all__ = ["settle", "settle_result"]


def settle(model: Model, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``theta`` with every effect's unreached parameters settled (see the module docstring); ``theta`` itself
    (a copy) where no effect of ``model`` has any. The model's output on ``t, u`` is unchanged by construction."""
    theta = np.array(theta, dtype=np.float64)
    if not isinstance(model, ComposedModel):
        return theta
    which = [i for i, e in enumerate(model.effects) if e.kind == "output" and hasattr(e, "settle")]
    if not which:
        return theta
    seen: dict[int, np.ndarray] = {}
    effects = list(model.effects)
    for i in which:  # copies that record what each of them is given; the model's own effects stay untouched
        e = copy.copy(effects[i])

        def output(th, tt, uu, y, _e=e, _i=i):
            seen[_i] = np.array(y, dtype=np.float64)
            return type(_e).output(_e, th, tt, uu, y)
        e.output = output  # type: ignore[method-assign]
        effects[i] = e
    ComposedModel(model.base, effects).simulate(theta, t, u)
    out = theta.copy()
    for i, sl in enumerate(model._slices):
        if i in seen:
            out[sl] = getattr(model.effects[i], "settle")(theta[sl].copy(), seen[i])
    return out


def settle_result(model: Model, res, t: np.ndarray, u: np.ndarray):
    """A fit result (:class:`~hyst_model.identify.result.FitResult`) with :func:`settle` applied to its parameters;
    the result itself where nothing moved (its RMSEs and residuals hold either way: the output is the same)."""
    th = settle(model, res.theta, t, u)
    if np.array_equal(th, np.asarray(res.theta, dtype=np.float64)):
        return res
    return dataclasses.replace(res, theta=th, params=model.unpack(th))
