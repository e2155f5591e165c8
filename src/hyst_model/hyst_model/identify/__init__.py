"""Identification: fit any :class:`~hyst_model.model.Model` to a record.

``fit(model, t, u, y, method='fast'|'epso'|'lsq', seed=None, split=0.25, progress=None) -> FitResult`` is the one
entry point; the estimator classes (:class:`FastFit`, :class:`EPSOFit`, :class:`LSQFit`) follow the scikit-learn
convention (``fit`` returns self; ``theta_``, ``params_``, ``result_``). See :mod:`.result` for the split.
"""
from __future__ import annotations

from collections.abc import Callable

from ..errors import FitError
from ..model import Model
from .base import Estimator, model_label
from .fast import FastFit
from .lsq import LSQFit
from .result import FitResult, Split, block_mask, make_split, rmse

__all__ = ["fit", "METHODS", "FastFit", "LSQFit", "EPSOFit", "Estimator", "FitResult", "Split", "make_split", "block_mask",
           "rmse", "model_label"]


def __getattr__(name):  # EPSO imports lazily (it is the slow path and pulls in the progress display)
    if name == "EPSOFit":
        from .epso import EPSOFit
        return EPSOFit
    raise AttributeError(name)


METHODS = ("fast", "epso", "lsq")


def fit(model: Model, t, u, y, method: str = "fast", seed: int | None = None, split=0.25,
        progress: Callable[[str], None] | bool | None = None, **options) -> FitResult:
    """Identify ``model`` on the record ``t, u, y`` (s, V, m) and return the :class:`FitResult`.

    Parameters
    ----------
    model : Model
        Model to fit (base or composed).
    method : {'fast', 'epso', 'lsq'}
        ``fast`` (default): equation-error start + output-error least squares; ``epso``: the thesis's extended
        PSO (3.22)–(3.27); ``lsq``: bounded least squares from the model defaults (the thesis's LSQM baseline).
    seed : int, optional
        Random seed (EPSO); the other methods are deterministic.
    split : float or (t0, t1) or None
        Validation hold-out, see :mod:`hyst_model.identify.result`.
    progress : callable or bool
        Status lines (``True``: to stderr).
    **options
        Passed to the estimator (e.g. ``n_starts`` for fast, ``iterations``/``particles`` for EPSO).
    """
    if method == "fast":
        est = FastFit(model, split=split, progress=progress, **options)
    elif method == "lsq":
        est = LSQFit(model, split=split, progress=progress, **options)
    elif method == "epso":
        from .epso import EPSOFit
        est = EPSOFit(model, seed=seed, split=split, progress=progress, **options)
    else:
        raise FitError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return est.fit(t, u, y).result_
