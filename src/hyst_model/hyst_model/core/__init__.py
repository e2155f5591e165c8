"""Numerical core: the MBW recursion and its parameters (numpy/numba only, no ROS)."""
from .bounded import DIVERGENCE_SPANS, mbw_bounded, probe_range
from .mbw import PARAM_NAMES, mbw_rest_state, mbw_simulate, mbw_simulate_batch, mbw_step
from .params import (BOUNDS, TABLE31_BOUNDS, THESIS_FIG37, THESIS_FIG38, THESIS_TABLE41, MBWParams,
                     from_continuous, pea_default, stage_model)

__all__ = [
    "DIVERGENCE_SPANS", "mbw_bounded", "probe_range",
    "PARAM_NAMES", "mbw_rest_state", "mbw_simulate", "mbw_simulate_batch", "mbw_step",
    "BOUNDS", "TABLE31_BOUNDS", "THESIS_FIG37", "THESIS_FIG38", "THESIS_TABLE41", "MBWParams", "from_continuous",
    "pea_default", "stage_model",
]
