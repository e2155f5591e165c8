"""hyst_model: hysteresis models, effects, identification, diagnostics, data IO and the ``hyst`` command line.

Layers: :mod:`hyst_model.core` (numerical, numpy/numba only) · :mod:`hyst_model.io` (bags, CSV, params files)
· ``*_node.py`` modules (thin rclpy nodes; the only place rclpy is imported).
"""
from .core import MBWParams, mbw_simulate, mbw_step, pea_default
from .model import MBWModel, Model, Param

__all__ = ["MBWParams", "mbw_simulate", "mbw_step", "pea_default", "Model", "MBWModel", "Param"]
