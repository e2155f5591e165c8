"""The controller protocol, the shared base class and the μ⁺/μ⁻ kernel of (4.15)–(4.16) / (5.26)–(5.27).

Timing convention (the thesis's indices)
----------------------------------------
``step(r_k, y)`` is called once per sample with the newest measurement ``y`` (the thesis's y_{k−1}) and the
reference ``r_k`` for the sample the returned command u_k will produce. The MBW model (3.21) has a direct
feed-through from u_k to y_k, which is what makes the laws (4.11) and (5.22) one-step inversions.

Units: every argument and return value is SI (m, V). Model-based laws run internally on the model's normalised
scale (``u_model = u / u_scale``, ``y_model = (y − offset) / y_scale``, :class:`hyst_model.core.MBWParams`).

Limits and anti-windup: the base class passes every raw command through :class:`CommandLimits` and stores the
*limited* command as u_{k−1}, so (4.12)/(5.23) never integrate a command the amplifier did not get.

Bumpless hand-over: :func:`hand_over` initialises a new controller from the previous controller's last command,
reference and the current measurement; all laws here are incremental in u (u_k = δ2·u_{k−1} + ν_k, or PID with the
integrator preloaded), and the slew limit bounds whatever step is left.
"""
from __future__ import annotations

import math
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numba import njit

from hyst_common.limits import CommandLimits
from hyst_common.profiles import PEA_LIMITS
from hyst_model.core import MBWParams

from .errors import ConfigError

__all__ = ["Controller", "BaseController", "ModelBased", "hand_over", "mu_select", "invert_nu", "check_model"]


@runtime_checkable
class Controller(Protocol):
    """What the loop, the node and the CLI need from a control algorithm."""

    name: str
    dt: float

    def reset(self, y0: float, u0: float, r0: float | None = None) -> None:
        """Start from measurement ``y0`` (m), current command ``u0`` (V) and last reference ``r0`` (m)."""

    def step(self, r_k: float, y_k: float) -> float:
        """One sample: reference for the next output (m), newest measurement (m) → command (V)."""

    def state(self) -> dict[str, float]:
        """Named scalars for plotting (SI where dimensional)."""


@njit(cache=True)
def mu_select(p: np.ndarray, y_prev: float, r_u: float, positive: bool, zeta0: float) -> float:
    """μ⁺ (4.15)/(5.26) when ``positive`` else μ⁻ (4.16)/(5.27), floored at ζ0.

    ``p`` is packed like :data:`hyst_model.core.PARAM_NAMES`. |y|·ψ·sign(y) = ψ·y is used. The floor only acts
    when a model violates Remark 4.1 (α_i < −|ψ_i|), where μ could otherwise reach zero and ν blow up.
    """
    ay = abs(y_prev)
    if positive:
        mu = p[0] - p[2] * y_prev - p[4] * ay + (p[1] - p[3] * y_prev - p[5] * ay) * r_u
    else:
        mu = p[0] + p[2] * y_prev - p[4] * ay + (p[1] + p[3] * y_prev - p[5] * ay) * r_u
    if not mu > zeta0:  # also catches NaN
        mu = zeta0
    return mu


@njit(cache=True)
def invert_nu(p: np.ndarray, y_prev: float, y_r: float, u_prev: float, r_u: float, exact: bool,
              zeta0: float) -> float:
    """Solve ν_k·μ(ν_k) = y_r for ν_k, the one-step inversion inside (4.14) and (5.25).

    ``exact=False`` is the thesis: μ is evaluated with the reference rate r_{u,k} (4.3)/(5.4) in place of the
    unknown input rate, ν = y_r/μ±. ``exact=True`` (hyst's default) uses the input rate itself: with
    v_{u,k} = |u_k − u_{k−1}| = |ν_k − (1 − δ2)·u_{k−1}| the equation ν·(A + B·|ν − c|) = y_r is a quadratic
    on each side of c = (1 − δ2)·u_{k−1}; A, B are the ζ1/ζ2 groups of μ± (A ≥ ζ0, B ≥ 0 under Remark 4.1), and
    the root with the sign of y_r that lies on its own side of c is returned (f is monotone there, so it is
    unique). Roots use the cancellation-free form 2y/(b + √(b² ± 4By)). Falls back to the thesis form when no
    branch qualifies (only possible for models violating Remark 4.1).
    """
    pos = y_r >= 0.0
    if not exact:
        return y_r / mu_select(p, y_prev, r_u, pos, zeta0)
    ay = abs(y_prev)
    if pos:
        a = p[0] - p[2] * y_prev - p[4] * ay
        b = p[1] - p[3] * y_prev - p[5] * ay
    else:
        a = p[0] + p[2] * y_prev - p[4] * ay
        b = p[1] + p[3] * y_prev - p[5] * ay
    if not a > zeta0:
        a = zeta0
    if not b > 0.0:
        return y_r / a
    c = (1.0 - p[7]) * u_prev
    # branch nu >= c:  B nu^2 + (A - B c) nu - y_r = 0
    b1 = a - b * c
    d1 = b1 * b1 + 4.0 * b * y_r
    if d1 >= 0.0:
        den = b1 + np.sqrt(d1)
        if den > 0.0:
            nu = 2.0 * y_r / den
            if nu >= c and (nu >= 0.0) == pos:
                return nu
    # branch nu < c:  B nu^2 - (A + B c) nu + y_r = 0
    b2 = a + b * c
    d2 = b2 * b2 - 4.0 * b * y_r
    if d2 >= 0.0:
        den = b2 + np.sqrt(d2)
        if den > 0.0:
            nu = 2.0 * y_r / den
            if nu < c and (nu >= 0.0) == pos:
                return nu
    return y_r / mu_select(p, y_prev, r_u, pos, zeta0)


def check_model(model: MBWParams) -> MBWParams:
    """Validate a model for control use; raise :class:`ConfigError` with the reason.

    Requires finite values, ζ1 > 0 and ζ2 ≥ 0 (Assumption 4.1), 0 < δ2 < 1 (the proofs of Theorems 4.1/5.1 bound
    u_k with it, after (4.21) and (5.39)) and 0 < δ1 < 1 (hyst's own requirement: with δ1 ≥ 1 the model's output
    does not relax at rest — δ1 = 1 holds it for ever, above 1 it grows), positive scales. Remark 4.1
    (α_i < −|ψ_i|) is reported by :attr:`MBWParams.control_positive` but not required: :func:`mu_select` floors μ
    instead.
    """
    vals = model.to_dict()
    bad = [k for k, v in vals.items() if not math.isfinite(v)]
    if bad:
        raise ConfigError(f"model parameters not finite: {', '.join(bad)}")
    if not model.zeta1 > 0 or model.zeta2 < 0:
        raise ConfigError("model needs zeta1 > 0 and zeta2 >= 0 (thesis Assumption 4.1)")
    if not (0 < model.delta1 < 1 and 0 < model.delta2 < 1):
        raise ConfigError("model needs 0 < delta2 < 1 for a bounded control input (Theorems 4.1, 5.1) and "
                          "0 < delta1 < 1 (a model that relaxes at rest)")
    if not (model.u_scale > 0 and model.y_scale > 0):
        raise ConfigError("model u_scale and y_scale must be positive")
    return model


def check_zeta0(zeta0: float, model: MBWParams) -> None:
    """Assumption 4.1 (and DMRAC's projection (5.12b)) asks ζ1 ≥ ζ0 > 0: a floor on μ above the model's own ζ1 is
    another law (zeta0 = 1 on the thesis's ζ1 = 0.40 tracked at 1 µm instead of 3 nm)."""
    if zeta0 > model.zeta1:
        raise ConfigError(f"zeta0 = {zeta0:g} exceeds the model's zeta1 = {model.zeta1:g}: Assumption 4.1 needs "
                          "zeta1 >= zeta0 > 0 (zeta0 is a floor on the model's own gain; (5.12b) would exclude it)")


#: Largest |reading| (m) a law without a model (PID) takes as a sample; beyond it the reading is corrupt and the
#: command holds.
MAX_READING = 1.0
#: The model-based laws take readings within this many model output units of the model's offset.
MODEL_READING_UNITS = 1000.0


class BaseController:
    """Shared bookkeeping: limits, u_{k−1}/r_{k−1} memory, NaN guards, step counter.

    Subclasses implement ``_law(r_k, y) -> float`` (raw SI command) and ``_on_reset(y0, u0, r0)``, and may
    override ``_commit(u)`` to learn the limited command.
    """

    name = "base"

    @classmethod
    def create(cls, model: MBWParams, dt: float, limits: CommandLimits, gains=None, initial="model"):
        """Build from the uniform arguments of :func:`hyst_control.controllers.make_controller`.

        Each law maps them to its own constructor and ignores what it does not use (``gains`` None = its
        defaults; ``initial``: DMRAC's initial estimates).
        """
        raise NotImplementedError(f"{cls.__name__} cannot be built by name")

    def __init__(self, dt: float, limits: CommandLimits | None = None) -> None:
        if not (dt > 0 and math.isfinite(dt)):
            raise ConfigError("dt must be a positive number of seconds")
        self.dt = float(dt)
        self.limits = limits or PEA_LIMITS
        self._u_prev = math.nan
        self._r_prev = math.nan
        self._y_prev = math.nan
        self._r_aim = math.nan   # the reference the newest measurement was aimed at (r passed one step earlier)
        self._k = 0
        self._du = 0.0  # last command increment u_{k−1} − u_{k−2} (V): the rate a successor continues from
        self._bad_inputs = 0
        self._saturated = 0
        # readings farther than this from the centre are taken for corrupt samples (the model-based laws narrow it
        # to their model's range); a metre is no micro-positioning stage's reading
        self._y_centre, self._y_reach = 0.0, MAX_READING

    # -- protocol -------------------------------------------------------------------------------------------
    def reset(self, y0: float, u0: float, r0: float | None = None) -> None:
        """Step 0: start from measurement ``y0`` (m), command ``u0`` (V), last reference ``r0`` (default y0)."""
        y0 = float(y0)
        if not math.isfinite(y0):
            raise ConfigError("reset needs a finite measurement y0")
        u0 = self.limits.apply(float(u0), math.nan, self.dt)
        r0 = y0 if r0 is None or not math.isfinite(r0) else float(r0)
        self._u_prev, self._r_prev, self._y_prev, self._k = u0, r0, y0, 0
        self._r_aim = r0
        self._du = 0.0
        self._on_reset(y0, u0, r0)

    def step(self, r_k: float, y_k: float) -> float:
        """One control sample (see the module docstring for the timing); returns the limited command (V)."""
        if self._u_prev != self._u_prev:  # never reset: start bumplessly from the safe output
            self.reset(y_k if math.isfinite(y_k) else 0.0, self.limits.v_safe, r_k)
        if not (math.isfinite(y_k) and abs(y_k - self._y_centre) <= self._y_reach):
            # a bad sample (non-finite, or a reading no stage of this model gives: 1e304 m made DPPC's λ inf and
            # ε NaN for good, PID's integrator NaN): hold the output, do not let it into the law's memory
            self._bad_inputs += 1
            return self._u_prev
        if not math.isfinite(r_k):
            self._bad_inputs += 1
            r_k = self._r_prev
        raw = self._law(r_k, y_k)
        u = self.limits.apply(raw, self._u_prev, self.dt)
        if u != raw:
            self._saturated += 1
        self._commit(u)
        self._du = u - self._u_prev
        self._r_aim = self._r_prev
        self._u_prev, self._r_prev, self._y_prev = u, r_k, y_k
        self._k += 1
        return u

    def state(self) -> dict[str, float]:
        # Tracking error of the newest measurement: y_{k-1} against the reference it was commanded for (r_{k-1},
        # passed one step earlier), not against r_k, which is the target of the command just computed.
        return {"error": self._y_prev - self._r_aim, "u": self._u_prev, "k": float(self._k),
                "saturated": float(self._saturated), "bad_inputs": float(self._bad_inputs)}

    def sync_applied(self, u_applied: float) -> None:
        """Take the voltage the amplifier actually applied for the newest sample (``effort[0]`` of the state)
        as u_{k−1}: when a command arrived late the stage ran on an older one, and (4.12)/(5.23) must continue
        from what really happened."""
        if math.isfinite(u_applied) and self._u_prev == self._u_prev:
            self._u_prev = float(u_applied)

    def notice_gap(self) -> None:
        """The newest sample does not follow the previous one (missed states); adaptive laws skip it."""

    # -- helpers --------------------------------------------------------------------------------------------
    @property
    def last_command(self) -> float:
        return self._u_prev

    @property
    def last_increment(self) -> float:
        """u_{k−1} − u_{k−2} (V): how fast the command was moving when this controller last ran."""
        return self._du

    @property
    def last_reference(self) -> float:
        return self._r_prev

    def _on_reset(self, y0: float, u0: float, r0: float) -> None:  # pragma: no cover - overridden
        pass

    def _law(self, r_k: float, y: float) -> float:  # pragma: no cover - overridden
        raise NotImplementedError

    def _commit(self, u: float) -> None:
        pass


class ModelBased(BaseController):
    """Base for laws built on the MBW model: holds the model, its packed vector and the scaling."""

    def __init__(self, model: MBWParams, dt: float, limits: CommandLimits | None = None) -> None:
        super().__init__(dt, limits)
        self.set_model(model)

    def set_model(self, model: MBWParams) -> None:
        """Swap the model at run time (the identification node pushes new ``model.*``); memory is kept.

        Memory held in model units is re-expressed in the new model's scaling first (:meth:`_rescale`): every fit
        picks its own ``y_scale``/``u_scale``, and a state left in the old units is a step in the command.
        """
        model = check_model(model)
        old = getattr(self, "model", None)
        if old is not None:
            self._rescale(old, model)
        self.model = model
        self._p = np.ascontiguousarray(model.vector)
        self._us = model.u_scale
        self._ys = model.y_scale
        self._off = model.offset
        # the fitting convention puts the output range at 8 model units: a reading 1000 units away is no sample
        self._y_centre, self._y_reach = model.offset, MODEL_READING_UNITS * model.y_scale

    def _rescale(self, old: MBWParams, new: MBWParams) -> None:
        """Re-express the law's model-unit memory from ``old``'s scaling in ``new``'s (overridden by the laws)."""

    @staticmethod
    def _pos(y_m: float, old: MBWParams, new: MBWParams) -> float:
        """A position in ``old``'s model units, in ``new``'s (through SI: offset and scale)."""
        return (y_m * old.y_scale + old.offset - new.offset) / new.y_scale

    def _ym(self, y: float) -> float:
        return (y - self._off) / self._ys


def hand_over(new: Any, old: Any | None, y: float, r: float | None = None) -> Any:
    """Bumpless transfer: start ``new`` from ``old``'s last command and reference and the measurement ``y``.

    With no previous controller (or one that never ran), ``new`` starts from ``v_safe``. Either may be a bare
    law or one wrapped (compensated, supervised): anything with the controller protocol and the memory properties.
    """
    if old is not None and math.isfinite(old.last_command):
        u0 = old.last_command
        r0 = old.last_reference if math.isfinite(old.last_reference) else r
        du = old.last_increment
    else:
        u0, r0, du = new.limits.v_safe, r, 0.0
    new.reset(y, u0, r0)
    law = new
    while getattr(law, "inner", law) is not law:  # through the wrappers (compensation, oscillation watch)
        law = law.inner
    law._du = du  # the command's rate in force, for laws that fade a start-up bump (OpenLoop); set on the law
    return new
