"""The stage's stroke from its MBW model, and the start-up check that a model is bounded (split from plant.py)."""
from __future__ import annotations


import numpy as np

from hyst_model.core import MBWParams

from .errors import ConfigError

__all__ = ["rest_stroke", "check_bounded"]


def rest_stroke(mbw: MBWParams, v_min: float, v_max: float) -> tuple[float, float]:
    """``(x_lo, x_hi)``: displacement (m) at ``v_min`` and ``v_max`` held at rest.

    Raises
    ------
    ConfigError
        The model has no finite increasing rest displacement over the range.
    """
    stroke = mbw.rest_range(v_min, v_max)
    if stroke is None:
        raise ConfigError("the MBW model has no finite, increasing rest displacement over [v_min, v_max]; "
                          "check the params file")
    return stroke


def check_bounded(cfg, p: np.ndarray, stroke: tuple[float, float]) -> None:
    """Refuse a model that diverges on a full-range 1 Hz and 50 Hz triangle sweep (a bad params file)."""
    from hyst_model.core import mbw_simulate

    span = stroke[1] - stroke[0]
    for f_hz in (1.0, 50.0):
        n = max(8, int(round(1.0 / (f_hz * cfg.dt))))
        tri = 1.0 - np.abs(np.linspace(-1.0, 1.0, n))
        u = (cfg.v_min + (cfg.v_max - cfg.v_min) * tri) / cfg.mbw.u_scale
        y = cfg.mbw.y_scale * mbw_simulate(p, np.ascontiguousarray(np.tile(u, 2)), 0.0, np.nan)
        if not (np.all(np.isfinite(y)) and np.max(np.abs(y)) < 100.0 * span + abs(cfg.mbw.offset)):
            raise ConfigError(f"the MBW model diverges on a {f_hz:g} Hz full-range sweep; check the params file")
