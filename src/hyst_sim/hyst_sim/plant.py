"""The simulated stage: amplifier limits, MBW hysteresis (thesis eq. 3.21) and optional physical effects.

Pure numerics (numpy/numba; scipy only to discretise a resonance). The sim node, ``hyst track``, the driver's
emulator and the diagnosis tests all build on this API::

    from hyst_sim.plant import Plant, PlantConfig

    plant = Plant.default(rate=1000.0, seed=0)   # pea_default() + 2 nm noise + 2 nm quantisation, dt = 1/rate
    plant.reset()                                 # rest at config.v_init (0 V); re-seeds the noise
    r = plant.step(75.0)                          # StepResult(y=<m>, u_applied=75.0, clipped=False)
    out = plant.run(u_array)                      # RunResult arrays, identical to repeated step()

    cfg = PlantConfig.for_profile("gma", rate=2000.0)            # profile limits, default stage, sensor
    cfg = PlantConfig.from_scenario("hidden_creep.yaml")          # default + hidden effects (never printed)
    cfg = cfg.with_strengths(delay=2, noise=0.0)                  # frozen: every change is a new config
    plant.reconfigure(cfg)                                        # swap config, keep the stage's state

Signal chain per sample ``k`` (see :mod:`hyst_sim.truth_effects` for each effect)::

    u_cmd ─ clip to [v_min, v_max] and slew_max·dt (NaN/inf hold the last value) ─▶ u_applied
    u_applied ─ delay ─▶ MBW(u/u_scale) held within the end stops · y_scale + offset
              ─ asymmetry ─ creep ─ saturation ─ dynamics ─▶ x
    x ─ + drift ─ + noise ─ quantisation ─▶ y (what the sensor reports)

With every effect off, ``y`` equals :meth:`hyst_model.core.MBWParams.simulate` of the applied voltage exactly
(the plant calls :func:`hyst_model.core.mbw_step`; there is no second MBW implementation). The MBW parameters
are per plant sample; ``mbw_substeps`` > 1 runs the recursion that many times per sample with the input held
(a model identified at ``dt/mbw_substeps``, e.g. a 2 kHz fit driven by a 1 kHz sim).

End stops: the stage's travel ends :data:`STOP_MARGIN` of the stroke beyond its rest positions at ``v_min``
and ``v_max``. An input far from anything the model was identified on (e.g. 0/150 V alternating every sample)
can drive the MBW state without bound; the stop holds it there and flags the sample (:data:`AT_STOP`), which
the sim node reports as a fault on ``/diagnostics``. The configuration is :mod:`.plant_config`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from hyst_common.limits import LIMIT_NONFINITE as CLIP_NONFINITE
from hyst_common.limits import LIMIT_RANGE as CLIP_RANGE
from hyst_common.limits import LIMIT_SLEW as CLIP_SLEW
from hyst_model.core import mbw_rest_state

from .errors import ConfigError, SimError
from .plant_kernel import (F_ASYM, F_CREEP, F_DA, F_DELAY, F_DQ, F_DR, F_DT, F_DW, F_DYN, F_HALF, F_NOISE, F_OFF,
                           F_QUANT, F_SAT, F_SATHI, F_SATLO, F_SATW, F_STEP, F_SUB, F_US, F_VMAX, F_VMIN, F_XMID,
                           F_YS, F_YSTOPHI, F_YSTOPLO, N_F, S_DIDX, S_DRIFT, S_DT_T, S_T, S_UA, S_UM, S_X, S_XQ, S_Y,
                           _plant_loop)
from .plant_config import PlantConfig, substeps_for
from .stroke import check_bounded, rest_stroke
from .truth_effects import asymmetry_kernel, saturation_kernel

__all__ = ["PlantConfig", "Plant", "StepResult", "RunResult", "CLIP_RANGE", "CLIP_SLEW", "CLIP_NONFINITE", "AT_STOP",
           "STOP_MARGIN", "substeps_for"]

#: Flag bit: the stage sat on a mechanical end stop during the sample (the model's hysteretic state was held
#: there). Not a clip of the command: the input was legal, the stage's physics would have left its travel.
AT_STOP = 8
#: End stops sit this fraction of the nominal stroke beyond the rest positions at v_min and v_max. A real
#: flexure stage's travel ends a little past its rated stroke; without a stop, an MBW model driven far outside
#: the excitations it was identified on (0/150 V alternating each sample) diverges to kilometres.
STOP_MARGIN = 0.25

_NORMAL_BLOCK = 4096  # rows of pre-drawn N(0,1) pairs; the stream is the same however it is consumed


class StepResult(NamedTuple):
    """One sample: sensor reading ``y`` (m), voltage ``u_applied`` (V), ``clipped`` (range/slew/non-finite)."""

    y: float
    u_applied: float
    clipped: bool
    at_stop: bool = False


class RunResult(NamedTuple):
    """A record: sensor reading ``y`` (m), applied voltage ``u_applied`` (V), ``flags`` (bits
    :data:`CLIP_RANGE` | :data:`CLIP_SLEW` | :data:`CLIP_NONFINITE`) and the true stage position ``x`` (m,
    before drift, noise and quantisation; for evaluation only, never published)."""

    y: np.ndarray
    u_applied: np.ndarray
    flags: np.ndarray
    x: np.ndarray

    @property
    def clipped(self) -> np.ndarray:
        return (self.flags & (CLIP_RANGE | CLIP_SLEW | CLIP_NONFINITE)) != 0

    @property
    def at_stop(self) -> np.ndarray:
        return (self.flags & AT_STOP) != 0


class Plant:
    """A simulated stage; see the module docstring for the API and the signal chain.

    Parameters
    ----------
    config : PlantConfig
        The stage. The plant starts at rest at ``config.v_init`` (as after :meth:`reset`).

    Raises
    ------
    ConfigError
        The MBW parameters do not give a bounded loop over the voltage range.
    """

    def __init__(self, config: PlantConfig):
        self._st = np.zeros(9)
        self._out1 = (np.empty(1), np.empty(1), np.empty(1, np.int8), np.empty(1))
        self._u1 = np.empty(1)
        self._apply(config, initial=True)
        self.reset()

    @classmethod
    def default(cls, rate: float = 1000.0, seed: int = 0) -> "Plant":
        """The embedded PEA stage: ``pea_default()``, 0–150 V, 2 nm noise + 2 nm quantisation, ``dt = 1/rate``."""
        return cls(PlantConfig.for_profile("pea", rate, seed=seed))

    # Properties -------------------------------------------------------------------------------------------------
    @property
    def config(self) -> PlantConfig:
        return self._cfg

    @property
    def dt(self) -> float:
        return self._cfg.dt

    @property
    def time(self) -> float:
        """Seconds since :meth:`reset` (samples taken × dt)."""
        return float(self._st[S_T])

    @property
    def u_applied(self) -> float:
        """Voltage applied at the last sample (V)."""
        return float(self._st[S_UA])

    @property
    def position(self) -> float:
        """True stage position at the last sample (m), before sensor effects; for evaluation, never published."""
        return float(self._st[S_X])

    @property
    def stroke_range(self) -> tuple[float, float]:
        """``(x_lo, x_hi)`` nominal displacement at ``v_min`` and ``v_max`` held (m)."""
        return self._stroke

    # Operation --------------------------------------------------------------------------------------------------
    def reset(self, v0: float | None = None) -> None:
        """Put the stage at rest at ``v0`` (V, default ``config.v_init``) and restart the random stream."""
        c = self._cfg
        v0 = c.v_init if v0 is None else float(v0)
        if not c.v_min <= v0 <= c.v_max:
            raise ConfigError(f"reset voltage {v0} V is outside [{c.v_min}, {c.v_max}] V")
        um = v0 / c.mbw.u_scale
        st = self._st
        st[:] = 0.0
        st[S_Y] = mbw_rest_state(self._p, um)
        st[S_UM] = um
        st[S_UA] = v0
        self._rng = np.random.default_rng(c.seed)
        self._normals = np.empty((0, 2))
        self._npos = 0
        x = c.mbw.y_scale * st[S_Y] + c.mbw.offset
        if c.effects.asymmetry.enabled:
            x = asymmetry_kernel(x, self._f[F_ASYM], self._f[F_XMID], self._f[F_HALF])
        st[S_XQ] = x
        st[S_X] = x  # at rest creep lags equal x, the dynamics are still, saturation is applied below
        if c.effects.saturation.enabled:
            st[S_X] = saturation_kernel(x, self._f[F_SATLO], self._f[F_SATHI], self._f[F_SATW])
        self._init_states(set(c.effects.strengths()))

    def step(self, u_cmd: float) -> StepResult:
        """Apply one command (V) for one sample and read the sensor; NaN/inf commands hold the last voltage."""
        self._u1[0] = u_cmd
        oy, ou, of, ox = self._out1
        self._advance(self._u1, oy, ou, of, ox)
        fl = int(of[0])
        return StepResult(float(oy[0]), float(ou[0]), bool(fl & (CLIP_RANGE | CLIP_SLEW | CLIP_NONFINITE)),
                          bool(fl & AT_STOP))

    def run(self, u_cmd) -> RunResult:
        """Apply a whole command record (V), continuing from the current state; equal to repeated :meth:`step`."""
        u = np.ascontiguousarray(np.asarray(u_cmd, dtype=np.float64).reshape(-1))
        n = u.shape[0]
        out = RunResult(np.empty(n), np.empty(n), np.empty(n, np.int8), np.empty(n))
        self._advance(u, out.y, out.u_applied, out.flags, out.x)
        return out

    def reconfigure(self, config: PlantConfig) -> None:
        """Swap in a new configuration without resetting the stage.

        The hysteresis state, applied voltage and time carry over; the state of every effect whose settings
        changed (or that was switched on) starts at the current operating point, so switching an effect on does
        not make the stage jump. A different ``dt`` re-discretises the effects and keeps their states.
        """
        old = self._cfg
        self._apply(config, initial=False)
        changed = {n for n in config.effects.strengths()
                   if getattr(config.effects, n) != getattr(old.effects, n)}
        if config.mbw != old.mbw or config.mbw_substeps != old.mbw_substeps:
            self._st[S_UM] = self._st[S_UA] / config.mbw.u_scale  # keep y_model: no jump, only a new law
        self._init_states(changed)

    # Internals --------------------------------------------------------------------------------------------------
    def _apply(self, cfg: PlantConfig, initial: bool) -> None:
        if not isinstance(cfg, PlantConfig):
            raise ConfigError("Plant needs a PlantConfig")
        p = np.ascontiguousarray(cfg.mbw.vector)
        stroke = cfg.stroke or rest_stroke(cfg.mbw, cfg.v_min, cfg.v_max)
        check_bounded(cfg, p, stroke)
        e = cfg.effects
        lo, hi = stroke
        span = hi - lo
        f = np.zeros(N_F)
        f[F_US], f[F_YS], f[F_OFF] = cfg.mbw.u_scale, cfg.mbw.y_scale, cfg.mbw.offset
        f[F_VMIN], f[F_VMAX], f[F_STEP] = cfg.v_min, cfg.v_max, cfg.slew_max * cfg.dt
        f[F_SUB], f[F_DT], f[F_DELAY] = cfg.mbw_substeps, cfg.dt, e.delay.strength
        f[F_ASYM], f[F_XMID], f[F_HALF] = e.asymmetry.strength, 0.5 * (lo + hi), 0.5 * span
        creep_a, f[F_CREEP] = e.creep.coefficients(cfg.dt)
        if e.saturation.enabled:
            s = e.saturation.strength * span
            two = e.saturation.two_sided if e.saturation.two_sided is not None else cfg.v_min < 0.0 < cfg.v_max
            f[F_SAT], f[F_SATW], f[F_SATHI] = 1.0, 2.0 * s, hi - s
            f[F_SATLO] = lo + s if two else -math.inf
        if e.dynamics.enabled:
            phi, gam = e.dynamics.coefficients(cfg.dt)
            f[F_DYN] = 1.0
        else:
            phi, gam = np.eye(2), np.zeros(2)
        if e.drift.enabled:
            d = e.drift
            f[F_DR], f[F_DW] = d.strength, 2.0 * math.pi / d.period
            f[F_DA] = d.sine * d.strength * d.period / (2.0 * math.pi)
            f[F_DQ] = d.walk * d.strength * math.sqrt(cfg.dt)
        f[F_NOISE], f[F_QUANT] = e.noise.strength, e.quantization.strength
        # mechanical end stops, on the model's own scale (y_scale > 0 is checked by MBWParams)
        f[F_YSTOPLO] = (lo - STOP_MARGIN * span - cfg.mbw.offset) / cfg.mbw.y_scale
        f[F_YSTOPHI] = (hi + STOP_MARGIN * span - cfg.mbw.offset) / cfg.mbw.y_scale
        self._cfg, self._p, self._f, self._stroke = cfg, p, f, (float(lo), float(hi))
        self._creep_a, self._phi, self._gam = creep_a, phi, gam
        if initial:
            self._creep_c, self._dz, self._dbuf = np.zeros(0), np.zeros(2), np.zeros(0)

    def _init_states(self, names: set[str]) -> None:
        """Start the named effects' states at the current operating point."""
        st = self._st
        if "creep" in names or self._creep_c.shape != self._creep_a.shape:
            self._creep_c = np.full(self._creep_a.shape[0], st[S_XQ])
        if "dynamics" in names:
            self._dz = np.array([st[S_X], 0.0])
        if "delay" in names or self._dbuf.shape[0] != int(self._f[F_DELAY]):
            self._dbuf = np.full(int(self._f[F_DELAY]), st[S_UA])
            st[S_DIDX] = 0.0
        if "drift" in names:
            st[S_DT_T] = 0.0  # the drift offset itself carries over: no jump in the reading
            if self._f[F_DR] == 0.0 and self._f[F_DA] == 0.0 and self._f[F_DQ] == 0.0:
                st[S_DRIFT] = 0.0  # switched off, it leaves the reading now, not again when switched back on

    def _take_normals(self, n: int) -> np.ndarray:
        if self._f[F_NOISE] == 0.0 and self._f[F_DQ] == 0.0:
            return np.zeros((n, 2)) if n > 1 else _ZERO_PAIR
        avail = self._normals.shape[0] - self._npos
        if avail < n:
            blocks = [self._normals[self._npos:]]
            need = n - avail
            while need > 0:
                blocks.append(self._rng.standard_normal((_NORMAL_BLOCK, 2)))
                need -= _NORMAL_BLOCK
            self._normals, self._npos = np.concatenate(blocks), 0
        out = self._normals[self._npos:self._npos + n]
        self._npos += n
        return out

    def _advance(self, u, oy, ou, of, ox) -> None:
        nrm = self._take_normals(u.shape[0])
        _plant_loop(u, self._p, self._f, self._st, self._creep_a, self._creep_c, self._phi, self._gam, self._dz,
                    self._dbuf, nrm, oy, ou, of, ox)
        if not math.isfinite(self._st[S_X]):
            raise SimError("the simulated stage diverged (non-finite displacement); check the model parameters")


_ZERO_PAIR = np.zeros((1, 2))
