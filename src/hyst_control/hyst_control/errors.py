"""Exceptions of hyst_control.

Every error a user can cause derives from :class:`ControlError`, itself a
:class:`hyst_model.errors.HystError`, so the ``hyst`` command line prints one line and exits 2.
"""
from __future__ import annotations

from hyst_model.errors import HystError

__all__ = ["ControlError", "ConfigError", "ReferenceError_", "LoopError"]


class ControlError(HystError):
    """Base class of hyst_control errors."""


class ConfigError(ControlError):
    """A controller gain, limit or model parameter is out of range or inconsistent."""


class ReferenceError_(ControlError):  # trailing underscore: do not shadow the builtin
    """A reference specification cannot be parsed or has impossible values."""


class LoopError(ControlError):
    """The closed loop could not run (no plant, diverged, non-finite output)."""
