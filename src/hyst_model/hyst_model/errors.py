"""Exceptions of hyst_model. Every error a user can cause derives from :class:`HystError`."""
from __future__ import annotations

__all__ = ["HystError", "DataError", "ParamsError", "FitError", "EffectError"]


from hyst_common.errors import HystError  # the root of every hyst error (re-exported)


class DataError(HystError):
    """Input data is missing, empty, truncated, non-finite or in the wrong units."""


class ParamsError(HystError):
    """A parameters file cannot be read, is incomplete, or would be overwritten."""


class FitError(HystError):
    """Identification failed (diverging model, too little data, no overlap)."""


class EffectError(HystError):
    """Unknown effect name, broken effect module, or an effect that does not fit the base model."""
