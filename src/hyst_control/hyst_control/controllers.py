"""The controllers by name: build one, parse a switching schedule, and the controller's view of a wrong model.

The control laws themselves are :mod:`.dppc`, :mod:`.dmrac` and :mod:`.pid`; the node (``controller_node``), the
in-process loop (``hyst_bringup.loop``) and ``hyst track`` choose them by the names in :data:`ALGORITHMS`.
"""
from __future__ import annotations

from hyst_common.limits import CommandLimits
from hyst_common.profiles import PEA_LIMITS
from hyst_model.core import MBWParams

from .base import BaseController
from .compensation import Compensation, wrap
from .dmrac import DMRAC, DMRACGains
from .dppc import DPPC, DPPCGains
from .errors import ConfigError, ControlError
from .pid import PID, OpenLoop, PIDGains

__all__ = ["ALGORITHMS", "make_controller", "parse_schedule", "mismatched"]

ALGORITHMS = ("dppc", "dmrac", "pid", "open_loop")


def make_controller(algorithm: str, model: MBWParams, dt: float, limits: CommandLimits | None = None,
                    gains=None, initial="model", compensation: Compensation | None = None):
    """Build a controller by name (``dppc``, ``dmrac``, ``pid``, ``open_loop``).

    With a :class:`~hyst_control.compensation.Compensation` that uses any effect, the law is wrapped in
    :class:`~hyst_control.compensation.Compensated` (the identified effects inverted around it).
    """
    limits = limits or PEA_LIMITS
    if algorithm == "dppc":
        c: BaseController = DPPC(model, dt, gains or DPPCGains(), limits)
    elif algorithm == "dmrac":
        c = DMRAC(model, dt, gains or DMRACGains(), initial, limits)
    elif algorithm == "pid":
        c = PID(dt, gains or PIDGains(), limits)
    elif algorithm == "open_loop":
        c = OpenLoop(model, dt, limits)
    else:
        raise ConfigError(f"unknown algorithm {algorithm!r}; choose one of {', '.join(ALGORITHMS)}")
    return wrap(c, compensation)


def parse_schedule(text: str) -> list[tuple[str, float]]:
    """``'dppc:3,pid:2'`` → ``[('dppc', 3.0), ('pid', 2.0)]``; raises ControlError with the accepted form."""
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        alg, _, sec = item.partition(":")
        try:
            dur = float(sec)
        except ValueError:
            raise ControlError(f"schedule entry {item!r}: use ALGORITHM:SECONDS, e.g. dppc:3") from None
        if alg not in ALGORITHMS or not dur > 0:
            raise ControlError(f"schedule entry {item!r}: algorithm in {', '.join(ALGORITHMS)}, seconds > 0")
        out.append((alg, dur))
    return out


def mismatched(model: MBWParams, fraction: float) -> MBWParams:
    """The controller's view of a stage with a relative model error ``fraction``.

    ζ1, ζ2 are scaled by (1 + F) (gain over-estimated) and ψ1, ψ2, α1, α2 by (1 − F) (hysteresis
    under-estimated); the ratio α_i/ψ_i and hence Remark 4.1 is unchanged.
    """
    if not -0.9 < fraction < 0.9:
        raise ConfigError("mismatch must lie in (-0.9, 0.9)")
    a, b = 1.0 + fraction, 1.0 - fraction
    return model.replace(zeta1=model.zeta1 * a, zeta2=model.zeta2 * a, psi1=model.psi1 * b,
                         psi2=model.psi2 * b, alpha1=model.alpha1 * b, alpha2=model.alpha2 * b)
