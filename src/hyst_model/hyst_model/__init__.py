"""hyst_model: hysteresis models, effects, identification, diagnostics, data IO and the ``hyst`` command line.

Layers: :mod:`hyst_model.core` (numerical, numpy/numba only) · :mod:`hyst_model.io` (bags, CSV, params files)
· ``*_node.py`` modules (thin rclpy nodes; the only place rclpy is imported).
"""
import hyst_common  # noqa: F401  first: single-threaded BLAS before numpy loads (hyst_common.blas)

# Lazy (PEP 562): ``hyst --help`` and an immediate argument error must not pay for numpy/numba (0.35 s of
# imports, several seconds on a loaded machine); the names load on first use.
_LAZY = {"MBWParams": "core", "mbw_simulate": "core", "mbw_step": "core", "pea_default": "core",
         "Model": "model", "MBWModel": "model", "Param": "model"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["single_thread_blas", "MBWParams", "mbw_simulate", "mbw_step", "pea_default", "Model", "MBWModel",
           "Param"]
