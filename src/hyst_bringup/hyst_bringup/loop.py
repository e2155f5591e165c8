"""In-process closed loop (no ROS): a controller from hyst_control against the simulated plant (hyst_sim).

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

from hyst_control.base import BaseController
from hyst_control.controllers import make_controller
from hyst_control.errors import ConfigError, LoopError
from hyst_control.reference import Reference, parse_reference
from hyst_model.core import pea_default
from hyst_sim.plant import Plant, PlantConfig

__all__ = ["LoopResult", "run_closed_loop", "default_plant", "warm_up", "SimPlant"]


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

    @property
    def position(self) -> float:
        """True stage position at the last sample (m), before sensor effects: for evaluation only."""
        return self.plant.position


def default_plant(rate: float = 2000.0, seed: int = 0, **strengths: float) -> SimPlant:
    """The embedded default stage (:meth:`hyst_sim.plant.Plant.default`: pea_default, 0–150 V, 2 nm noise and
    2 nm quantisation) at ``rate``, with optional effect strengths (``creep=0.02``, ``delay=1``, ...)."""
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
    #: True stage position per sample (m) where the plant reports one (a simulation): what the stage did, as
    #: against what its sensor read (a sensor's own drift is in ``y`` only).
    x: np.ndarray | None = None

    def _in_window(self, a: np.ndarray) -> np.ndarray:
        """The samples of ``a`` inside the metric window (t ≥ ``skip``)."""
        return a[self.t >= self.skip]

    @property
    def error(self) -> np.ndarray:
        """Tracking error y − r (m) inside the metric window."""
        return self._in_window(self.y - self.r)

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.error ** 2)))

    @property
    def rmse_position(self) -> float:
        """RMSE of the true position against the reference (m) inside the metric window; NaN without ``x``."""
        if self.x is None:
            return math.nan
        return float(np.sqrt(np.mean(self._in_window(self.x - self.r) ** 2)))

    @property
    def mae(self) -> float:
        """Maximum absolute error (thesis ch. 4.3.2 'MAE'), m."""
        return float(np.max(np.abs(self.error)))

    def at_limits(self, v_min: float, v_max: float) -> float:
        """Share of the run's commands on ``v_min`` or ``v_max`` (to 1e-6 of the range): where the error is the
        range's, not the tracking's."""
        tol = 1e-6 * (v_max - v_min)
        return float(np.mean((self.u <= v_min + tol) | (self.u >= v_max - tol)))

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.y)) and np.all(np.isfinite(self.u)))

    def summary(self) -> dict:
        """Metrics as plain values (m, V); ``rmse_position`` where the plant knows its true position (a
        simulation: a sensor's own drift is in the reading, ``rmse``, not in the position)."""
        out = {"algorithm": self.algorithm, "reference": self.reference, "rate": self.rate,
               "samples": int(self.t.size), "skip": self.skip, "rmse": self.rmse, "mae": self.mae,
               "u_min": float(np.min(self.u)), "u_max": float(np.max(self.u)), "finite": self.finite}
        if self.x is not None:
            out["rmse_position"] = self.rmse_position
        return out


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
    x = np.empty(n) if hasattr(plant, "position") else None
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
        if x is not None:
            x[k] = plant.position
        if record:
            s = controller.state()
            for name in record:
                rec[name][k] = s.get(name, math.nan)
    if not np.all(np.isfinite(y)):
        raise LoopError("the plant output became non-finite")
    spec = reference if isinstance(reference, str) else ref.shape
    return LoopResult(controller.name, spec, 1.0 / dt, t, r, y, u, rec, skip, x)


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

