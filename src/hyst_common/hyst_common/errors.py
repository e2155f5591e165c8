"""The root of every hyst error. Each package derives its own small exception module from :class:`HystError`."""
from __future__ import annotations

__all__ = ["HystError"]


class HystError(Exception):
    """Base class: command lines and nodes print its message on one line and exit 2, without a traceback."""
