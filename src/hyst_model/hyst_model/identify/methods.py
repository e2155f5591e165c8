"""The fit methods by name: a registry as data, light enough for a command line's ``--help`` to read.

Each entry names the estimator's module and class (imported only when a fit runs: EPSO is the slow path and pulls
in the progress display) and whether it takes a random seed. ``hyst fit --method``, the identification node's
``method`` parameter and :func:`hyst_model.identify.fit` all read :data:`METHODS`; adding a method is its estimator
module plus one line here.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["Method", "METHODS", "estimator_class"]


@dataclass(frozen=True)
class Method:
    """One fit method.

    Attributes
    ----------
    module : str
        Module of :mod:`hyst_model.identify` holding the estimator (``fast``).
    cls : str
        Estimator class name (an :class:`~hyst_model.identify.base.Estimator`).
    seeded : bool
        The estimator takes ``seed`` (random search); the others are deterministic.
    """

    module: str
    cls: str
    seeded: bool = False


#: The fit methods by name, the default first.
METHODS: dict[str, Method] = {
    "fast": Method("fast", "FastFit"),      # equation-error start + output-error least squares
    "epso": Method("epso", "EPSOFit", seeded=True),  # the thesis's extended PSO (3.22)-(3.27)
    "lsq": Method("lsq", "LSQFit"),         # bounded least squares from the model defaults (LSQM baseline)
}


def estimator_class(name: str) -> type:
    """The estimator class of method ``name`` (imported now); ``KeyError`` for an unknown name."""
    m = METHODS[name]
    return getattr(importlib.import_module(f"{__package__}.{m.module}"), m.cls)
