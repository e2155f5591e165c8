"""Discrete model reference adaptive control (DMRAC), thesis ch. 5.2, eqs. (5.3)–(5.27).

Per sample (model units, ν_k = u_k − δ2·u_{k−1}):

* Reference model (5.3): y_{d,k} = r_k + a_m·y_{d,k−1}. hyst receives the *desired trajectory* y_d (the
  ``/stage/reference`` topic) and recovers the model input r_k = y_{d,k} − a_m·y_{d,k−1}, so that the closed loop
  makes e_k = y_k − y_{d,k} (5.7) obey e_k = a_m·e_{k−1} (5.40) with a perfect model.
* Estimation error (5.9): ε_{k−1} = δ1·y_{k−2} + ν_{k−1}·μ̂_{k−1} − y_{k−1}, evaluated with
  :func:`hyst_model.core.mbw_step` on the command actually applied, whose rate v_{u,k−1} = |u_{k−1} − u_{k−2}|
  is known once u_{k−1} has been sent (the thesis uses r_{u,k−1} (5.4) there; the control law below still has to
  use r_{u,k} because u_k is not known yet). The regressors of (5.12)–(5.17) and N_k (5.11) use the same rate.
* Adaptation (5.12)–(5.17) with κ1 for ζ̂1, ψ̂1, α̂1 (G1) and κ2 for ζ̂2, ψ̂2, α̂2 (G2) (κ1 = κ2 = κ is the single
  gain of (5.12)–(5.17); separate gains are the thesis's last experiments, Figs. 5.27–5.31), projections:
  ζ̂1 ≥ ζ0 (5.12b), ζ̂2 ≥ 0 (5.13b), α̂1 ≤ −|ψ̂1| − ϱ (5.16b), α̂2 ≤ −|ψ̂2| (5.17b). The thesis enforces
  (5.16b)/(5.17b) by clipping α̂ alone; that is not a projection and can *increase* the Lyapunov function (5.19)
  (the property test in test_dmrac.py found θ̂ = (1, 0, 1, 0, 0, 0), ν = y = 1 as a counterexample). hyst
  projects (ψ̂_i, α̂_i) orthogonally onto the same convex set {α ≤ −|ψ| − ϱ}, so (5.20) holds as stated, and
  iterates on the projected estimates (not on the primed values). Also beyond the thesis every estimate is also kept
  in a box |θ| ≤ ``theta_max`` (ψ̂ is unprojected in (5.14)–(5.15) and drifts under noise, the classic parameter-drift
  problem), and an optional dead zone stops adaptation on estimation errors below the noise.
* Control (5.24)–(5.27): y_{r,k} = r_k − (δ1 − a_m)·y_{k−1}; ν_k = y_{r,k}/μ̂⁺ (y_{r,k} ≥ 0) or y_{r,k}/μ̂⁻; then
  u_k = δ2·u_{k−1} + ν_k (5.23).

δ1, δ2 (and the SI scaling) come from the model; ζ, ψ, α are estimated. Initial estimates: the model itself
(``initial='model'``) or the thesis's Table 5.3 sets CS0–CS3 (:data:`TABLE53`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from hyst_common.limits import CommandLimits
from hyst_common.params import not_finite, param
from hyst_model.core import MBWParams, mbw_step

from .base import ModelBased, check_model, check_zeta0, invert_nu
from .errors import ConfigError

__all__ = ["DMRACGains", "DMRAC", "TABLE53", "ESTIMATE_NAMES", "dmrac_adapt"]

#: Names of the six estimates in :meth:`DMRAC.estimates` order (as published on /controller/state).
ESTIMATE_NAMES = ("zeta1_hat", "zeta2_hat", "psi1_hat", "psi2_hat", "alpha1_hat", "alpha2_hat")

#: Thesis Table 5.3: initial estimates (ζ1, ζ2, ψ1, ψ2, α1, α2). CS0 = identified initial (GMA), CS1 = 2.2×,
#: CS2 = 10×, CS3 = 100× (sign pattern as printed; CS1's positive α is projected at the first step).
TABLE53: dict[str, tuple[float, ...]] = {
    "cs0": (0.008, 0.008, -0.002, -0.002, -0.005, -0.005),
    "cs1": (0.0176, 0.0176, 0.0044, 0.0044, 0.0011, 0.0011),
    "cs2": (0.08, 0.08, -0.02, -0.02, -0.05, -0.05),
    "cs3": (0.8, 0.8, -0.2, -0.2, -0.5, -0.5),
}


@dataclass(frozen=True)
class DMRACGains:
    """DMRAC gains (thesis ch. 5.3: κ = 0.01; Remark 5.1: 0 < κ < 2).

    Attributes
    ----------
    kappa1, kappa2 : float
        Adaptation gains of the G1 (ζ1, ψ1, α1) and G2 (ζ2, ψ2, α2) estimates; equal values = the single κ.
    a_m : float
        Reference-model pole (5.3), |a_m| < 1; it is also the closed-loop error pole (5.40).
    zeta0, varrho : float
        Projection constants of (5.12b) and (5.16b).
    theta_max : float
        Box on every estimate (model units); beyond the thesis.
    deadzone : float
        No adaptation while |ε| (m) is below this (0 = the thesis).
    exact_rate : bool
        Invert μ̂ with the input rate itself (:func:`hyst_control.base.invert_nu`); False = r_{u,k} (5.4).
    """

    kappa1: float = param(0.01, 1e-6, 1.99, "adaptation gain κ1 of ζ1, ψ1, α1 (5.12)-(5.17)")
    kappa2: float = param(0.01, 0.0, 1.99, "adaptation gain κ2 of ζ2, ψ2, α2")
    a_m: float = param(0.1, -0.99, 0.99, "reference-model pole a_m (5.3) = closed-loop error pole")
    zeta0: float = param(1e-3, 1e-9, 1.0, "projection bound ζ0 (5.12b)")
    varrho: float = param(1e-4, 1e-9, 1.0, "projection margin ϱ (5.16b)")
    theta_max: float = param(10.0, 0.01, 1e3, "box on every estimate (model units)")
    deadzone: float = param(0.0, 0.0, 1e-6, "no adaptation below this estimation error (m)")
    exact_rate: bool = param(True, doc="invert with the input rate (true) or r_u (5.4)")

    @classmethod
    def single(cls, kappa: float, **kw) -> "DMRACGains":
        """One adaptation gain κ for all six laws, as in (5.12)–(5.17)."""
        return cls(kappa1=kappa, kappa2=kappa, **kw)

    def __post_init__(self) -> None:
        bad = not_finite(self)
        if bad:
            raise ConfigError(f"DMRAC {bad}")
        if not (0 < self.kappa1 < 2 and 0 <= self.kappa2 < 2):
            raise ConfigError("DMRAC needs 0 < kappa1 < 2 and 0 <= kappa2 < 2 (Remark 5.1)")
        if not abs(self.a_m) < 1:
            raise ConfigError("DMRAC needs |a_m| < 1 (5.3)")
        if not (self.zeta0 > 0 and self.varrho > 0 and self.theta_max > self.zeta0):
            raise ConfigError("DMRAC needs zeta0 > 0, varrho > 0, theta_max > zeta0")
        if not self.deadzone >= 0:
            raise ConfigError("DMRAC deadzone must be >= 0")


def _check_sets(gains: DMRACGains, model: MBWParams) -> None:
    """The Lyapunov step (5.19)–(5.20) needs the true parameters inside the projection sets: ζ1 ≥ ζ0 (5.12b), every
    value within the box θ_max, and — for a model that satisfies Remark 4.1 — α1 ≤ −|ψ1| − ϱ (5.16b), ϱ "very
    small" (Remark 5.1). Outside them the estimates are pushed away from the truth: ϱ = 1 tracked at 3.5 µm,
    θ_max = 0.01 at 2.2 µm, instead of 3 nm."""
    vals = dict(zeta1=model.zeta1, zeta2=model.zeta2, psi1=model.psi1, psi2=model.psi2, alpha1=model.alpha1,
                alpha2=model.alpha2)
    check_zeta0(gains.zeta0, model)
    big = [k for k, v in vals.items() if abs(v) > gains.theta_max]
    if big:
        raise ConfigError(f"theta_max = {gains.theta_max:g} excludes the model's {big[0]} = {vals[big[0]]:g}: the "
                          "box must hold the true parameters (model units)")
    if model.alpha1 < -abs(model.psi1) and model.alpha1 > -abs(model.psi1) - gains.varrho:
        raise ConfigError(f"varrho = {gains.varrho:g} exceeds the model's Remark 4.1 margin "
                          f"{-abs(model.psi1) - model.alpha1:.3g} (alpha1 = {model.alpha1:g}, psi1 = "
                          f"{model.psi1:g}): (5.16b) would exclude the true alpha1; Remark 5.1 takes it very small")


@njit(cache=True)
def _project_cone(psi, alpha, rho):
    """Euclidean projection of (ψ, α) onto the convex set {α ≤ −|ψ| − ρ} (Remark 5.2's admissible set)."""
    if alpha <= -abs(psi) - rho:
        return psi, alpha
    s = 1.0 if psi >= 0.0 else -1.0
    d = 0.5 * (alpha + s * psi + rho)  # distance along the normal (s, 1)/√2 of the boundary ray, ×1/√2
    p2 = psi - s * d
    if p2 * s < 0.0:  # past the apex: the apex is nearest
        return 0.0, -rho
    return p2, alpha - d


@njit(cache=True)
def dmrac_adapt(th, eps, nu, y_pp, v, k1, k2, zeta0, varrho, tmax):
    """Adaptation (5.11)–(5.17) in place on ``th`` = (ζ1, ζ2, ψ1, ψ2, α1, α2) for one past sample.

    ``eps`` = ε_{k−1}, ``nu`` = ν_{k−1}, ``y_pp`` = y_{k−2}, ``v`` = the rate term of sample k−1.
    """
    n2 = 1.0 + (nu * nu + 2.0 * (nu * y_pp) ** 2) * (1.0 + v * v)  # (5.11) squared
    g = eps / n2
    ay = abs(y_pp)
    z1 = abs(th[0] - k1 * g * nu)  # (5.12a)
    z2 = abs(th[1] - k2 * g * v * nu)  # (5.13a)
    p1 = th[2] + k1 * g * abs(nu) * y_pp  # (5.14)
    p2 = th[3] + k2 * g * v * abs(nu) * y_pp  # (5.15)
    a1 = th[4] + k1 * g * nu * ay  # (5.16a)
    a2 = th[5] + k2 * g * v * nu * ay  # (5.17a)
    p1, a1 = _project_cone(p1, a1, varrho)  # (5.16b), orthogonal form
    p2, a2 = _project_cone(p2, a2, 0.0)  # (5.17b), orthogonal form
    # Box (beyond the thesis); shrinking ψ inside the box keeps α admissible, so both sets stay satisfied.
    th[0] = min(max(z1, zeta0), tmax)  # (5.12b)
    th[1] = min(z2, tmax)  # (5.13b): |.| already keeps it >= 0
    th[2] = min(max(p1, -tmax + varrho), tmax - varrho)
    th[3] = min(max(p2, -tmax), tmax)
    th[4] = min(max(a1, -tmax), -abs(th[2]) - varrho)  # exact again after rounding in the projection
    th[5] = min(max(a2, -tmax), -abs(th[3]))


@njit(cache=True)
def _dmrac_law(pe, th, have_past, y_m, u_p, y_pp, u_pp, yd_m, ydp_m, ydpp_m, a_m, k1, k2, zeta0, varrho, tmax, dz,
               exact):
    """One DMRAC sample in model units (one compiled call: the step-cost budget is ~20 µs in Python).

    Adaptation on the last completed sample ((5.9) via :func:`hyst_model.core.mbw_step` with the applied
    command, then (5.12)–(5.17)), then the control law (5.3), (5.24)–(5.27). Returns (ν_k, ε_{k−1}).
    """
    eps = 0.0
    if have_past:
        pe[:6] = th
        eps = mbw_step(pe, y_pp, u_p, u_pp) - y_m  # (5.9): δ1·y_{k-2} + ν_{k-1}·μ̂_{k-1} − y_{k-1}
        if abs(eps) > dz:
            dmrac_adapt(th, eps, u_p - pe[7] * u_pp, y_pp, abs(u_p - u_pp), k1, k2, zeta0, varrho, tmax)
    pe[:6] = th
    r_model = yd_m - a_m * ydp_m  # (5.3) solved for the reference-model input r_k
    r_u = abs(r_model - (ydp_m - a_m * ydpp_m))  # (5.4): |r_k − r_{k−1}|, model output scale
    y_r = r_model - (pe[6] - a_m) * y_m  # (5.24)
    return invert_nu(pe, y_m, y_r, u_p, r_u, exact, zeta0), eps  # (5.25)-(5.27)


class DMRAC(ModelBased):
    """Discrete model reference adaptive controller (5.3), (5.9)–(5.17), (5.22)–(5.27).

    Parameters
    ----------
    model : MBWParams
        Supplies δ1, δ2, the SI scaling and (with ``initial='model'``) the initial estimates.
    dt : float
        Sample period (s).
    gains : DMRACGains
    initial : str or sequence of 6 floats
        ``'model'``, one of ``'cs0'``–``'cs3'`` (Table 5.3), or explicit (ζ1, ζ2, ψ1, ψ2, α1, α2).
    limits : CommandLimits
    """

    name = "dmrac"

    @classmethod
    def create(cls, model, dt, limits, gains=None, initial="model"):
        """See :meth:`hyst_control.base.BaseController.create`."""
        return cls(model, dt, gains or DMRACGains(), initial, limits)

    def __init__(self, model: MBWParams, dt: float, gains: DMRACGains = DMRACGains(),
                 initial: str | tuple = "model", limits: CommandLimits | None = None) -> None:
        super().__init__(model, dt, limits)
        _check_sets(gains, self.model)
        self.gains = gains
        self.initial = initial
        self._th0 = self._initial_vector(initial)
        self._th = self._th0.copy()
        self._pe = self._p.copy()  # packed estimate vector (δ's from the model) for mu_select / mbw_step
        self._eps = 0.0
        self._nu = 0.0
        self._yd_prev = math.nan
        self._yd_pp = math.nan  # y_{d,k-2} (SI): r_{k-1} of (5.4)
        self._y_pp = math.nan  # y_{k-2} (model units)
        self._u_pp = math.nan  # u_{k-2} (model units)
        self._have_past = False

    def _initial_vector(self, initial) -> np.ndarray:
        if isinstance(initial, str):
            key = initial.lower()
            if key == "model":
                return self._p[:6].copy()
            if key not in TABLE53:
                raise ConfigError(f"unknown DMRAC initial estimate {initial!r}; use model, cs0, cs1, cs2 or cs3")
            return np.array(TABLE53[key], dtype=np.float64)
        th = np.asarray(initial, dtype=np.float64)
        if th.shape != (6,) or not np.all(np.isfinite(th)):
            raise ConfigError("explicit DMRAC initial estimates need 6 finite numbers")
        return th.copy()

    def set_gains(self, gains: DMRACGains) -> None:
        _check_sets(gains, self.model)
        self.gains = gains

    def set_model(self, model: MBWParams) -> None:
        """New δ1, δ2 and scaling; the adapted estimates are kept (they are the controller's, not the model's),
        re-expressed in the new scaling (:meth:`_rescale`); the gains' sets checked against it."""
        if hasattr(self, "gains"):
            _check_sets(self.gains, check_model(model))
        super().set_model(model)
        if hasattr(self, "_pe"):
            self._pe[6:] = self._p[6:]

    def _rescale(self, old: MBWParams, new: MBWParams) -> None:
        """Estimates and memory in the new model units, so the same physical law runs on.

        With y′ = c·y (c = y_scale_old/y_scale_new) and u′ = b·u (b = u_scale_old/u_scale_new), (3.21) keeps its
        form when ζ1′ = c·ζ1/b, ψ1′ = ψ1/b, α1′ = α1/b (terms in ν) and ζ2′ = c·ζ2/b², ψ2′ = ψ2/b², α2′ = α2/b²
        (terms in ν·v_u). Without this a push from a fit with another y_scale (6.6, 12.7, 20.3 µm per unit
        were seen) left a 1.8 µm transient that took ≈ 5 s of adaptation to settle.
        """
        if not hasattr(self, "_th"):
            return
        c, b = old.y_scale / new.y_scale, old.u_scale / new.u_scale
        f = np.array([c / b, c / b ** 2, 1 / b, 1 / b ** 2, 1 / b, 1 / b ** 2])
        self._th *= f
        self._th0 = self._th0 * f
        g = self.gains
        dmrac_adapt(self._th, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g.zeta0, g.varrho, g.theta_max)  # projections, box
        self._eps *= c
        if self._have_past:
            self._y_pp = self._pos(self._y_pp, old, new)
            self._u_pp *= b

    @property
    def estimates(self) -> np.ndarray:
        """Current (ζ̂1, ζ̂2, ψ̂1, ψ̂2, α̂1, α̂2), model units."""
        return self._th.copy()

    def _on_reset(self, y0: float, u0: float, r0: float) -> None:
        self._th = self._th0.copy()
        g = self.gains
        # Make the initial estimates admissible (the projections (5.12b)–(5.17b) at k = 0).
        dmrac_adapt(self._th, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g.zeta0, g.varrho, g.theta_max)
        self._yd_prev = self._yd_pp = r0  # at rest: r_{k-1} = (1 − a_m)·y_d
        self._have_past = False
        self._eps = 0.0
        self._nu = 0.0

    def notice_gap(self) -> None:
        """Skip the next adaptation step: y_{k−2}, u_{k−2} are not the previous sample's."""
        self._have_past = False

    def _law(self, r_k: float, y: float) -> float:
        g = self.gains
        ys, us, off = self._ys, self._us, self._off
        nu, eps = _dmrac_law(
            self._pe, self._th, self._have_past, (y - off) / ys, self._u_prev / us, self._y_pp, self._u_pp,
            (r_k - off) / ys, (self._yd_prev - off) / ys, (self._yd_pp - off) / ys, g.a_m, g.kappa1, g.kappa2,
            g.zeta0, g.varrho, g.theta_max, g.deadzone / ys, g.exact_rate)
        if self._have_past:
            self._eps = eps
        self._nu = nu
        self._yd_pp = self._yd_prev
        self._yd_prev = r_k
        self._y_pp = (y - off) / ys
        self._u_pp = self._u_prev / us
        self._have_past = True
        return (self._pe[7] * self._u_pp + nu) * us  # (5.23)

    def state(self) -> dict[str, float]:
        s = super().state()
        s.update(epsilon=self._eps * self._ys, nu=self._nu * self._us,
                 **dict(zip(ESTIMATE_NAMES, map(float, self._th))))
        return s
