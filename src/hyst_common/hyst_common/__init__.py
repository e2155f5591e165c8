"""hyst_common: the bottom of the hyst packages.

* :mod:`hyst_common.errors` — :class:`HystError`, the root of every hyst error;
* :mod:`hyst_common.profiles` — the hardware facts: the PEA and GMA stage profiles and their limits;
* :mod:`hyst_common.limits` — the one range-and-slew limiter core (driver, sim and controller) and the
  controller's :class:`~hyst_common.limits.CommandLimits` around it;
* :mod:`hyst_common.params` — parameters described once on a dataclass (default, range, description);
* :mod:`hyst_common.blas` — single-threaded BLAS for hyst's processes (set here, before anything loads numpy);
* :mod:`hyst_common.runtime` — real-time scheduling and ROS-argument-aware command-line helpers (rclpy-free);
* :mod:`hyst_common.node` — the one way to run a node (:func:`~hyst_common.node.run_node`) and all-or-nothing
  parameter sets (:class:`~hyst_common.node.AtomicParametersNode`): with the ``*_node.py`` modules, the only
  place that imports rclpy (docs/ARCHITECTURE.md);
* :mod:`hyst_common.stopping` — the runner's stop flag and the watchdog that bounds a stop (rclpy-free);
* :mod:`hyst_common.startup` — Ctrl-C while a node process is still importing: one line, exit 0.

It depends on no other hyst package; every other package imports it first.
"""
from .blas import single_thread_blas

# Before anything loads numpy (and with it BLAS): hyst's own processes use one BLAS thread (see .blas).
single_thread_blas()

from .errors import HystError  # noqa: E402 - after single_thread_blas(), which must run before numpy loads
from .startup import quiet_start  # noqa: E402

quiet_start()  # hyst_* executables only: a SIGINT before main takes over is one line, not a traceback

__all__ = ["HystError", "single_thread_blas"]
