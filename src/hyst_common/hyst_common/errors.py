"""The root of every hyst error. Each package derives its own small exception module from :class:`HystError`."""
from __future__ import annotations

__all__ = ["HystError", "ConfigError"]


class HystError(Exception):
    """Base class: command lines and nodes print its message on one line and exit 2, without a traceback."""


class ConfigError(HystError, ValueError):
    """A hardware fact asked for does not exist or a limit is inconsistent (unknown profile, ``v_min >= v_max``).

    A ``ValueError`` too, so every node's parameter callback and start-up (which catch ``ValueError``) report it
    as one line, like their own packages' configuration errors.
    """
