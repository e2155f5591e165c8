"""Identification: fit any :class:`~hyst_model.model.Model` to a record.

``fit(model, t, u, y, method='fast'|'epso'|'lsq', seed=None, split=0.25, progress=None) -> FitResult`` is the one
entry point; the estimator classes (:class:`FastFit`, :class:`EPSOFit`, :class:`LSQFit`) follow the scikit-learn
convention (``fit`` returns self; ``theta_``, ``params_``, ``result_``). See :mod:`.result` for the split.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING

from hyst_common.blas import one_blas_thread

from ..errors import FitError
from .methods import METHODS, estimator_class
from .result import FitResult, Split, block_mask, make_split, rmse

if TYPE_CHECKING:
    from ..model import Model

__all__ = ["fit", "METHODS", "FastFit", "LSQFit", "EPSOFit", "Estimator", "FitResult", "Split", "make_split",
           "block_mask", "rmse", "model_label"]


#: Names imported on first use (numba, scipy; EPSO pulls in the progress display), so that ``hyst --help`` and
#: ``hyst fit --help`` can read :data:`METHODS` without them.
_LAZY = {"FastFit": "fast", "LSQFit": "lsq", "EPSOFit": "epso", "Estimator": "base", "model_label": "base"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(name)


@one_blas_thread
def fit(model: Model, t, u, y, method: str = "fast", seed: int | None = None, split=0.25,
        progress: Callable[[str], None] | bool | None = None, **options) -> FitResult:
    """Identify ``model`` on the record ``t, u, y`` (s, V, m) and return the :class:`FitResult`.

    Parameters
    ----------
    model : Model
        Model to fit (base or composed).
    method : str
        A name in :data:`~hyst_model.identify.methods.METHODS`:
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
    if method not in METHODS:
        raise FitError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if METHODS[method].seeded:
        options["seed"] = seed
    est = estimator_class(method)(model, split=split, progress=progress, **options)
    return est.fit(t, u, y).result_
