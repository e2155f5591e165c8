"""hyst_control: DPPC, DMRAC, PID and open-loop controllers for hysteretic actuators, references.

Numerical core (no rclpy): :mod:`.base`, :mod:`.dppc`, :mod:`.dmrac`, :mod:`.pid` (its command notch
:mod:`.notch`; command limits: :mod:`hyst_common.limits`), :mod:`.controllers` (by name), :mod:`.reference`. Thin
nodes: ``controller_node``, ``reference_node``, ``excite_node``. It depends on hyst_model and hyst_common only: the
closed loop against the simulated stage (``run_closed_loop``, ``hyst track``, ``hyst demo``, ``hyst_loop_node``) is
in ``hyst_bringup``.
"""
import hyst_common  # noqa: F401  first: sets single-threaded BLAS before numpy loads (hyst_common.blas)
from hyst_common.limits import CommandLimits
from hyst_common.profiles import GMA_LIMITS, PEA_LIMITS

from .base import BaseController, Controller, hand_over
from .dmrac import DMRAC, TABLE53, DMRACGains
from .dppc import DPPC, THESIS_TABLE42, DPPCGains
from .errors import ConfigError, ControlError, LoopError, ReferenceError_
from .controllers import ALGORITHMS, make_controller, mismatched, parse_schedule
from .notch import Notch, notch_tf
from .pid import PID, OpenLoop, PIDGains
from .reference import TABLE_REFERENCES, Reference, parse_reference

__all__ = [
    "BaseController", "Controller", "hand_over",
    "DMRAC", "DMRACGains", "TABLE53",
    "DPPC", "DPPCGains", "THESIS_TABLE42",
    "ConfigError", "ControlError", "LoopError", "ReferenceError_",
    "CommandLimits", "PEA_LIMITS", "GMA_LIMITS",
    "ALGORITHMS", "make_controller", "mismatched", "parse_schedule",
    "PID", "PIDGains", "OpenLoop", "Notch", "notch_tf",
    "Reference", "TABLE_REFERENCES", "parse_reference",
]
