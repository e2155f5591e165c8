"""hyst_model: hysteresis models, effects, identification, diagnostics, data IO and the ``hyst`` command line.

Layers: :mod:`hyst_model.core` (numerical, numpy/numba only) · :mod:`hyst_model.io` (bags, CSV, params files)
· ``*_node.py`` modules (thin rclpy nodes; the only place rclpy is imported).
"""
from .blas import single_thread_blas

# Before anything loads numpy (and with it BLAS): hyst's own processes use one BLAS thread (see .blas).
single_thread_blas()

from .core import MBWParams, mbw_simulate, mbw_step, pea_default  # noqa: E402  (after the BLAS setting on purpose)
from .model import MBWModel, Model, Param  # noqa: E402

__all__ = ["single_thread_blas", "MBWParams", "mbw_simulate", "mbw_step", "pea_default", "Model", "MBWModel", "Param"]
