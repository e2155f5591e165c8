"""Parameters described once, on the dataclass that holds them: default, range and description of each field.

:func:`param` is a dataclass field whose metadata carries the allowed range and a one-line description;
:func:`table` reads a dataclass back as ``{name: Spec}``. A node declares its ROS parameters (with
``FloatingPointRange`` from the range), and a command line names its options, from the dataclass alone, so there
is no second table to keep in step with the defaults. rclpy-free.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

__all__ = ["Spec", "param", "table", "not_finite"]


@dataclass(frozen=True)
class Spec:
    """One described parameter.

    Attributes
    ----------
    default : object
        The field's default (its type is the parameter's type: float, int, bool or str).
    lo, hi : float or None
        Allowed range (inclusive), ``None`` when the parameter has none (booleans, strings).
    description : str
        One line, units in parentheses.
    """

    default: Any
    lo: float | None
    hi: float | None
    description: str


def param(default: Any, lo: float | None = None, hi: float | None = None, doc: str = "") -> Any:
    """A dataclass field with a default, an allowed range ``[lo, hi]`` and a description (for :func:`table`)."""
    return dataclasses.field(default=default, metadata={"range": (lo, hi), "description": doc})


def table(cls: type) -> dict[str, Spec]:
    """``{field name: Spec}`` of a dataclass whose fields are :func:`param` (in field order).

    Raises
    ------
    TypeError
        ``cls`` is not a dataclass, or a field has no default or no description (every parameter is described).
    """
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is dataclasses.MISSING or "description" not in f.metadata:
            raise TypeError(f"{cls.__name__}.{f.name}: declare it with hyst_common.params.param(default, lo, hi, doc)")
        lo, hi = f.metadata["range"]
        out[f.name] = Spec(f.default, lo, hi, f.metadata["description"])
    return out


def not_finite(obj: Any) -> str:
    """'' when every numeric field of the dataclass instance ``obj`` is finite; else the first that is not (the
    classes' own checks cover order and sign, not infinity: ``lambda0=inf`` passed and made every ε NaN). The
    declared ranges bound what a user sets; the laws' own derating may go beyond them (a_m 0.995)."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if not isinstance(v, bool) and isinstance(v, (int, float)) and not math.isfinite(v):
            return f"{f.name} = {v!r} is not a finite number"
    return ""
