"""The controllers by name (a registry as data), a switching schedule, and the controller's view of a wrong model.

:data:`CONTROLLERS` maps each name to its law class and its gains dataclass. The gains' fields are declared with
:func:`hyst_common.params.param` (default, range, description), and the controller node declares its
``<name>.<gain>`` parameters from them, ``hyst track --gain`` names them, and :func:`make_controller` builds the law
through its ``create`` classmethod (:meth:`hyst_control.base.BaseController.create`). Adding a controller is its
module (the law with ``create``, its gains dataclass) plus one line in :data:`CONTROLLERS`.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hyst_common.limits import CommandLimits
from hyst_common.params import Spec, table
from hyst_common.profiles import PEA_LIMITS
from hyst_model.core import MBWParams

from .base import BaseController
from .compensation import Compensation, wrap
from .dmrac import DMRAC, DMRACGains
from .dppc import DPPC, DPPCGains
from .errors import ConfigError, ControlError
from .pid import PID, OpenLoop, PIDGains

__all__ = ["Law", "CONTROLLERS", "ALGORITHMS", "gain_table", "make_controller", "make_supervised", "parse_schedule",
           "mismatched"]


@dataclass(frozen=True)
class Law:
    """One registered controller.

    Attributes
    ----------
    cls : type
        The law, a :class:`~hyst_control.base.BaseController` with a ``create`` classmethod.
    gains : type or None
        Its frozen gains dataclass, every field a :func:`hyst_common.params.param`; None: no gains.
    """

    cls: type[BaseController]
    gains: type | None = None


#: The controllers by name, in the order they are listed (node parameters, ``--help``, ``hyst track``).
CONTROLLERS: dict[str, Law] = {
    "dppc": Law(DPPC, DPPCGains),
    "dmrac": Law(DMRAC, DMRACGains),
    "pid": Law(PID, PIDGains),
    "open_loop": Law(OpenLoop),
}
#: Names of the controllers.
ALGORITHMS = tuple(CONTROLLERS)


def gain_table() -> dict[str, tuple[type, dict[str, Spec]]]:
    """``{name: (gains dataclass, {gain: Spec})}`` of every controller with gains: what the node declares."""
    return {name: (law.gains, table(law.gains)) for name, law in CONTROLLERS.items() if law.gains is not None}


def make_controller(algorithm: str, model: MBWParams, dt: float, limits: CommandLimits | None = None,
                    gains=None, initial="model", compensation: Compensation | None = None):
    """Build a controller by name (:data:`ALGORITHMS`).

    Parameters
    ----------
    algorithm : str
        A key of :data:`CONTROLLERS`.
    model : MBWParams
        The stage model (unused by the PID).
    dt : float
        Sample period (s).
    limits : CommandLimits, optional
        Command range and slew; the PEA profile's by default.
    gains : optional
        The law's gains dataclass; its defaults when None.
    initial : str or tuple
        DMRAC's initial estimates (``model``, ``cs0``-``cs3``, or six values).
    compensation : Compensation, optional
        With any effect used, the law is wrapped in :class:`~hyst_control.compensation.Compensated` (the
        identified effects inverted around it).

    Raises
    ------
    ConfigError
        Unknown name (the message lists the known ones) or a setting the law refuses.
    """
    law = CONTROLLERS.get(algorithm)
    if law is None:
        raise ConfigError(f"unknown algorithm {algorithm!r}; choose one of {', '.join(ALGORITHMS)}")
    return wrap(law.cls.create(model, dt, limits or PEA_LIMITS, gains, initial), compensation)


def make_supervised(algorithm: str, model: MBWParams, dt: float, limits: CommandLimits | None = None,
                    gains=None, initial="model", compensation: Compensation | None = None, act: bool = True,
                    rebuild: Callable[[str, Any], Any] | None = None):
    """:func:`make_controller` wrapped in a :class:`~hyst_control.supervisor.Supervised` oscillation watch that
    rebuilds it with derated gains when the command rings: by default with the same model, limits and
    compensation; ``rebuild(algorithm, gains)`` instead builds from what is in force at that time (the node:
    a model pushed since)."""
    from .supervisor import Supervised, output_span

    lim = limits or PEA_LIMITS
    law = make_controller(algorithm, model, dt, lim, gains, initial, compensation)
    if gains is None and CONTROLLERS[algorithm].gains is not None:
        gains = law.gains

    def same(alg: str, g):
        if alg != algorithm:  # the fallback to the open-loop inverse: refused for a model that runs away open loop
            from .controller_settings import model_divergence
            model_divergence(alg, model, compensation, lim, dt)
        return make_controller(alg, model, dt, lim, g, initial, compensation)

    return Supervised(law, algorithm, gains, rebuild or same, dt, (lim.v_min, lim.v_max), act,
                      output_span(model, (lim.v_min, lim.v_max)))


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
