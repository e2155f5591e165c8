"""Hysteresis models: the registry of fittable base models and the thesis's continuous-time references.

``BASE_MODELS`` maps a name to ``factory(config: dict) -> Model``; factories read the keys they need from the
config (missing keys take defaults) and ignore the rest, so one params file ``model:`` section can carry them all.

=====  ====================================================  =========================================
name   model                                                 config keys
=====  ====================================================  =========================================
mbw    Modified Bouc-Wen (3.21), rate dependent             u_scale (V), y_scale (m), offset_bound (m)
bw     discrete Bouc-Wen (3.19) = MBW without rate terms    same
pi     Prandtl-Ishlinskii (2.13), analytic inverse          n_play, r_max (V), u_scale, y_scale, offset_bound
=====  ====================================================  =========================================

:func:`data_config` chooses those normalisations from a record, so that the thesis's bounds (Table 3.1) and
defaults make sense for any actuator: the input is mapped to ±10 model units (the amplitude of the thesis's
sine tests), the output so that ζ1 ≈ 0.4 explains its range.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from ..model import MBWModel, Model
from .continuous import backlash_like, bw_bound, bw_general, bw_special, dahl
from .pi import PIModel, pi_inverse, pi_simulate, play_operators

__all__ = ["BASE_MODELS", "data_config", "backlash_like", "dahl", "bw_special", "bw_general", "bw_bound",
           "PIModel", "pi_simulate", "pi_inverse", "play_operators"]


def _f(config: Mapping, key: str, default: float) -> float:
    v = config.get(key, default)
    try:
        return float(v)
    except (TypeError, ValueError):
        raise ValueError(f"config {key}={v!r} is not a number") from None


def _mbw(config: Mapping) -> Model:
    return MBWModel(_f(config, "u_scale", 1.0), _f(config, "y_scale", 1.0), rate=True,
                    offset_bound=_f(config, "offset_bound", 1e-3))


def _bw(config: Mapping) -> Model:
    return MBWModel(_f(config, "u_scale", 1.0), _f(config, "y_scale", 1.0), rate=False,
                    offset_bound=_f(config, "offset_bound", 1e-3))


def _pi(config: Mapping) -> Model:
    return PIModel(int(_f(config, "n_play", 10)), _f(config, "r_max", 1.0), _f(config, "y_scale", 1.0),
                   _f(config, "offset_bound", 1e-3), _f(config, "u_scale", 1.0))


#: name -> factory(config) -> Model
BASE_MODELS: dict[str, Callable[[Mapping], Model]] = {"mbw": _mbw, "bw": _bw, "pi": _pi}


def data_config(u: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Normalisations for fitting any registered model to data ``u`` (V), ``y`` (m).

    ``u_scale`` maps the largest |u| to 10 model units; ``y_scale`` makes the output range equal 0.4 × the model
    input range (so ζ1 starts near its typical value and far from its bounds); ``offset_bound`` admits any
    offset within twice the largest |y|; ``r_max`` is half the input range (PI thresholds).
    """
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    umax = float(np.max(np.abs(u))) if u.size else 0.0
    u_scale = umax / 10.0 if umax > 0 else 1.0
    u_range = float(np.ptp(u)) / u_scale if u.size else 0.0
    y_range = float(np.ptp(y)) if y.size else 0.0
    y_scale = y_range / (0.4 * u_range) if (y_range > 0 and u_range > 0) else 1.0
    ymax = float(np.max(np.abs(y))) if y.size else 0.0
    r_max = 0.5 * float(np.ptp(u)) if u.size and np.ptp(u) > 0 else 1.0
    return {"u_scale": u_scale, "y_scale": y_scale, "offset_bound": max(2.0 * ymax, 1e-9), "r_max": r_max}
