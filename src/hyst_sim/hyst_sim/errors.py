"""Exceptions of hyst_sim. Every error a user can cause derives from :class:`SimError` (a ``HystError``)."""
from __future__ import annotations

from hyst_model.errors import HystError

__all__ = ["SimError", "ConfigError", "ScenarioError", "BagError"]


class SimError(HystError):
    """Base class of hyst_sim errors; the ``hyst`` CLI prints the message and exits with code 2."""


class ConfigError(SimError, ValueError):
    """A plant, profile or effect setting is out of range or inconsistent (the message says which and why)."""


class ScenarioError(SimError):
    """A scenario or params file cannot be read or is malformed.

    Messages name the file and the structural problem but never echo hidden effect names or values.
    """


class BagError(SimError):
    """A bag cannot be opened, written or replayed (missing directory, existing output, unknown topic)."""
