"""argparse types for hyst's command lines: a bad number is one ``error: argument --seed: ...`` line and exit 2.

``type=int`` alone let ``--seed -1`` through to numpy (a ValueError traceback) and ``--iterations 0`` to EPSO.
"""
from __future__ import annotations

import argparse
import math

__all__ = ["nonneg_int", "positive_int", "positive_float"]


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"needs a whole number, got {text!r}") from None


def nonneg_int(text: str) -> int:
    """A whole number >= 0 (seeds)."""
    v = _int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"needs a whole number >= 0, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """A whole number >= 1 (counts)."""
    v = _int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"needs a whole number >= 1, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0 (rates, durations)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"needs a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"needs a finite number > 0, got {text!r}")
    return v
