"""In-process closed loop (no ROS): a controller from this package against the simulated plant.

Used by ``hyst track``, the tracking tables (bench/bench_tracking.py) and the tests. The stage is first held at
the reference's starting point for ``settle`` seconds under the same controller (as an experiment starts from a
settled stage), then the reference runs for ``seconds``; metrics cover the run only.

Timing per sample k (the thesis's indices): the controller gets r_k and the newest measurement y_{k−1} and
returns u_k; the plant applies u_k and produces y_k; the tracking error is e_k = y_k − r_k on the *measured*
output (noise included, as on the rig).
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hyst_common.limits import CommandLimits
from hyst_common.profiles import PEA_LIMITS
from hyst_model.core import MBWParams, pea_default

from .base import BaseController
from .compensation import Compensation, wrap
from .dmrac import DMRAC, DMRACGains
from .dppc import DPPC, DPPCGains
from .errors import ConfigError, ControlError, LoopError
from .pid import PID, OpenLoop, PIDGains
from .reference import Reference, parse_reference

__all__ = ["ALGORITHMS", "LoopResult", "make_controller", "mismatched", "run_closed_loop", "default_plant",
           "warm_up",
           "SimPlant", "parse_schedule"]

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


class SimPlant:
    """Adapter over :class:`hyst_sim.plant.Plant`: ``reset(u0) -> y`` and ``step(u) -> y`` in SI.

    The first reading after a reset is the true rest position (the sim's reset takes no sample).
    """

    def __init__(self, plant) -> None:
        self.plant = plant
        self.dt = plant.dt

    def reset(self, u0: float = 0.0) -> float:
        self.plant.reset(u0)
        return self.plant.position

    def step(self, u: float) -> float:
        return self.plant.step(u).y


def default_plant(rate: float = 2000.0, seed: int = 0, **strengths: float) -> SimPlant:
    """The embedded default stage (:meth:`hyst_sim.plant.Plant.default`: pea_default, 0–150 V, 2 nm noise and
    2 nm quantisation) at ``rate``, with optional effect strengths (``creep=0.02``, ``delay=1``, ...)."""
    from hyst_sim.plant import Plant, PlantConfig  # noqa: PLC0415 - sibling package, numerical core

    if strengths:
        return SimPlant(Plant(PlantConfig.for_profile("pea", rate, seed=seed).with_strengths(**strengths)))
    return SimPlant(Plant.default(rate=rate, seed=seed))


@dataclass
class LoopResult:
    """Samples of one closed-loop run (SI) and its metrics."""

    algorithm: str
    reference: str
    rate: float
    t: np.ndarray
    r: np.ndarray
    y: np.ndarray
    u: np.ndarray
    states: dict = field(default_factory=dict)

    #: Seconds after t = 0 excluded from the metrics (set by :func:`run_closed_loop` ``skip``).
    skip: float = 0.0

    @property
    def error(self) -> np.ndarray:
        """Tracking error y − r (m) inside the metric window."""
        keep = self.t >= self.skip
        return (self.y - self.r)[keep]

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.error ** 2)))

    @property
    def mae(self) -> float:
        """Maximum absolute error (thesis ch. 4.3.2 'MAE'), m."""
        return float(np.max(np.abs(self.error)))

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.y)) and np.all(np.isfinite(self.u)))

    def summary(self) -> dict:
        return {"algorithm": self.algorithm, "reference": self.reference, "rate": self.rate,
                "samples": int(self.t.size), "skip": self.skip, "rmse": self.rmse, "mae": self.mae,
                "u_min": float(np.min(self.u)), "u_max": float(np.max(self.u)), "finite": self.finite}


def run_closed_loop(controller: BaseController, reference: Reference | str, seconds: float = 1.0,
                    plant=None, settle: float = 0.2, record: tuple[str, ...] = (), skip: float = 0.0) -> LoopResult:
    """Run ``controller`` against ``plant`` (default :func:`default_plant`) tracking ``reference``.

    Parameters
    ----------
    controller : BaseController
        Its ``dt`` sets the loop rate.
    reference : Reference or str
        A :class:`Reference` or a spec for :func:`parse_reference`.
    seconds : float
        Length of the run (s), after ``settle``.
    plant : object, optional
        ``reset(u0) -> y`` and ``step(u) -> y`` in SI (:class:`SimPlant`); default :func:`default_plant` at the
        controller's rate.
    settle : float
        Seconds of holding r(0) before the run.
    skip : float
        Seconds at the start of the run left out of RMSE/MAE (e.g. a step's transient).
    record : tuple of str
        Names from ``controller.state()`` to record per sample into ``LoopResult.states``.

    Raises
    ------
    LoopError
        The plant produced a non-finite output.
    """
    ref = parse_reference(reference) if isinstance(reference, str) else reference
    if not (seconds > 0 and settle >= 0):
        raise ConfigError("seconds must be positive and settle >= 0")
    dt = controller.dt
    plant = plant if plant is not None else default_plant(rate=1.0 / dt)
    n_settle = int(round(settle / dt))
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    r, _ = ref.sample(t)
    r = np.atleast_1d(r)
    # A compensated delay needs the reference ahead by its preview (the loop knows the whole reference).
    preview = float(getattr(controller, "preview", 0.0))
    r_ctrl = np.atleast_1d(ref.sample(t + preview)[0]) if preview > 0 else r
    y = np.empty(n)
    u = np.empty(n)
    rec = {k: np.empty(n) for k in record}
    u_cmd = controller.limits.v_safe
    y_meas = plant.reset(u_cmd)
    controller.reset(y_meas, u_cmd, float(r[0]))
    r0 = float(r[0])
    # The settle holds r(0); with a preview the last samples of it already aim at the run's first references.
    ts = (np.arange(n_settle) - n_settle) * dt + preview
    r_settle = np.where(ts < 0.0, r0, np.atleast_1d(ref.sample(np.maximum(ts, 0.0))[0])) if preview > 0 else \
        np.full(n_settle, r0)
    for j in range(n_settle):
        u_cmd = controller.step(float(r_settle[j]), y_meas)
        y_meas = plant.step(u_cmd)
    for k in range(n):
        u_cmd = controller.step(float(r_ctrl[k]), y_meas)
        y_meas = plant.step(u_cmd)
        y[k] = y_meas
        u[k] = u_cmd
        if record:
            s = controller.state()
            for name in record:
                rec[name][k] = s.get(name, math.nan)
    if not np.all(np.isfinite(y)):
        raise LoopError("the plant output became non-finite")
    spec = reference if isinstance(reference, str) else ref.shape
    return LoopResult(controller.name, spec, 1.0 / dt, t, r, y, u, rec, skip)


def warm_up(algorithms: Sequence[str], rate: float = 2000.0) -> float:
    """Run each algorithm for a few samples on the default plant, off line; returns the seconds it took.

    The recursions are numba-compiled on first use and cached on disk (``cache=True``). On a fresh install the
    first real-time loop would otherwise compile them inside its 0.5 ms periods — the first ``make demo`` after
    setup missed 6133 of 6252 ticks and never reached DMRAC. Called before starting the timed processes, which
    then load the cached machine code.
    """

    t0 = time.perf_counter()
    for alg in algorithms:
        run_closed_loop(make_controller(alg, pea_default(), 1.0 / rate), "sine:5", 0.01,
                        plant=default_plant(rate), settle=0.0)
    return time.perf_counter() - t0

