"""Discrete prescribed performance control (DPPC), thesis ch. 4.2, eqs. (4.3)–(4.16).

Law per sample (model units, ν convention ν_k = u_k − δ2·u_{k−1}, see :mod:`hyst_model.core.mbw`):

1. performance function (4.7): λ_k = (1 − ω)·λ_{k−1} + ω·λ∞
2. transformed error (4.10): ε_{k−1} = ½·ln((λ_{k−1}·h̲ + e_{k−1}) / (λ_{k−1}·h̄ − e_{k−1})), e = y − r (4.6)
3. y_{r,k} (4.13) = (r_k − δ1·y_{k−1}) + λ_k·(h̄·e^{2χε} − h̲)/σ_k,  σ_k = 1 + e^{2χε}
4. ν_k = y_{r,k} / μ⁺ if y_{r,k} ≥ 0 else y_{r,k} / μ⁻ (4.14)–(4.16), with r_{u,k} = |r_k − r_{k−1}| (4.3)
5. u_k = δ2·u_{k−1} + ν_k (4.12)

Step 0 (4.9): λ_0 is chosen so that −h̲λ_0 < e_0 < h̄λ_0 (the gain ``lambda0``, widened if the initial error
needs it), ν_0 = 0 and u_0 = the command in force (bumpless; the thesis starts from u_0 = 0).

Out-of-funnel policy (hyst's choice; the thesis assumes (4.8) always holds, which (4.17)–(4.19) prove only for a
perfect model without noise): before (4.10) is evaluated, if e_{k−1} is not strictly inside the funnel with a
margin, i.e. outside (−ρ·h̲·λ_{k−1}, ρ·h̄·λ_{k−1}) with ρ = ``funnel_margin`` (default 0.9), Step 0 is re-run:
λ_{k−1} is widened to |e_{k−1}|/(ρ·h) so the error sits at the margin, and (4.7) then shrinks the funnel back
towards λ∞ at rate ω. Hence |ε| ≤ ½·ln((h̲ + ρ·h̄)/((1−ρ)·h̄)) on the upper side (and its mirror below); for
h̲ = h̄ (Table 4.2) ½·ln((1+ρ)/(1−ρ)) = 1.47 for ρ = 0.9: ε, ν and u are always finite and
bounded, whatever noise, model mismatch or bump hit the stage. Re-initialisations are counted
(``funnel_resets`` in :meth:`DPPC.state`).

Beyond the thesis: ``exact_rate`` (default on) inverts μ with the input rate v_{u,k} itself instead of the
reference rate r_{u,k} of (4.3) (see :func:`hyst_control.base.invert_nu`); ``exact_rate=False`` is the thesis.
Also beyond the thesis (off by default, ``ki`` = 0): an integral of the tracking error shifts the target, removing the
steady-state error that any model mismatch leaves (with χ → 0 the loop is a one-step model inversion without
integral action).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

from hyst_common.limits import CommandLimits
from hyst_common.params import not_finite, param
from hyst_model.core import MBWParams

from .base import ModelBased, check_model, check_zeta0, invert_nu
from .errors import ConfigError

__all__ = ["DPPCGains", "DPPC", "THESIS_TABLE42", "dppc_nu"]


@dataclass(frozen=True)
class DPPCGains:
    """DPPC gains (thesis Table 4.2), funnel sizes in metres.

    The thesis's λ0 = 20, λ∞ = 0.4 are read as µm (its errors are reported in µm on a 30 µm stage).
    """

    lambda0: float = param(20e-6, 1e-9, 1e-3, "initial funnel half-width λ0 (m), Table 4.2: 20 µm")
    lambda_inf: float = param(0.4e-6, 1e-10, 1e-4, "final funnel half-width λ∞ (m), Table 4.2: 0.4 µm")
    omega: float = param(0.01, 1e-6, 0.999, "funnel decay per sample ω (4.7)")
    chi: float = param(0.1, 1e-3, 0.999, "error contraction χ (4.11); larger = gentler, more robust")
    h_lower: float = param(1.0, 0.01, 100.0, "lower funnel factor h̲ (4.8)")
    h_upper: float = param(1.0, 0.01, 100.0, "upper funnel factor h̄ (4.8)")
    funnel_margin: float = param(0.9, 0.1, 0.99, "out-of-funnel re-initialisation margin ρ")
    ki: float = param(0.0, 0.0, 0.99, "integral of the error on the target (beyond thesis; 0 = off)")
    zeta0: float = param(1e-3, 1e-9, 1.0, "lower bound on μ (Assumption 4.1)")
    exact_rate: bool = param(True, doc="invert with the input rate (true) or the reference rate r_u (4.3)")

    def __post_init__(self) -> None:
        bad = not_finite(self)
        if bad:
            raise ConfigError(f"DPPC {bad}")
        if not (self.lambda0 > self.lambda_inf > 0):
            raise ConfigError("DPPC needs lambda0 > lambda_inf > 0 (4.7)")
        if not 0 < self.omega < 1:
            raise ConfigError("DPPC omega must lie in (0, 1) for a decreasing λ_k (4.7)")
        if not 0 < self.chi < 1:
            raise ConfigError("DPPC chi must lie in (0, 1) (4.11)")
        if not (self.h_lower > 0 and self.h_upper > 0):
            raise ConfigError("DPPC h_lower and h_upper must be positive (4.8)")
        if not 0 < self.funnel_margin < 1:
            raise ConfigError("funnel_margin must lie in (0, 1)")
        if not 0 <= self.ki < 1:
            raise ConfigError("DPPC ki must lie in [0, 1)")
        if not self.zeta0 > 0:
            raise ConfigError("zeta0 must be positive (Assumption 4.1)")


#: Table 4.2 (λ in metres).
THESIS_TABLE42 = DPPCGains()


@njit(cache=True)
def dppc_nu(p, y_prev, e_prev, r_k, r_u, u_prev, exact, lam_prev, lam_inf, omega, chi, h_lo, h_hi, margin, zeta0):
    """One DPPC law evaluation in model units; returns (ν_k, λ_k, ε_{k−1}, λ_{k−1} used, reset flag).

    Implements the out-of-funnel re-initialisation, (4.10), (4.7), (4.13)–(4.16).
    """
    reset = 0.0
    if e_prev >= margin * h_hi * lam_prev:
        lam_prev = e_prev / (margin * h_hi)
        reset = 1.0
    elif e_prev <= -margin * h_lo * lam_prev:
        lam_prev = -e_prev / (margin * h_lo)
        reset = 1.0
    eps = 0.5 * math.log((lam_prev * h_lo + e_prev) / (lam_prev * h_hi - e_prev))  # (4.10)
    lam = (1.0 - omega) * lam_prev + omega * lam_inf  # (4.7)
    x = math.exp(2.0 * chi * eps)
    sigma = 1.0 + x
    y_r = (r_k - p[6] * y_prev) + lam * (h_hi * x - h_lo) / sigma  # (4.13)
    nu = invert_nu(p, y_prev, y_r, u_prev, r_u, exact, zeta0)  # (4.14)-(4.16)
    return nu, lam, eps, lam_prev, reset


class DPPC(ModelBased):
    """Discrete prescribed performance controller (4.7)–(4.16) on an MBW model.

    Parameters
    ----------
    model : MBWParams
        The stage model (thesis Table 4.1 on the PEA scale by default: :func:`hyst_model.core.pea_default`).
    dt : float
        Sample period (s).
    gains : DPPCGains
        Table 4.2 by default.
    limits : CommandLimits
        Command range and slew.
    """

    name = "dppc"

    @classmethod
    def create(cls, model, dt, limits, gains=None, initial="model"):
        """See :meth:`hyst_control.base.BaseController.create`."""
        return cls(model, dt, gains or DPPCGains(), limits)

    def __init__(self, model: MBWParams, dt: float, gains: DPPCGains = THESIS_TABLE42,
                 limits: CommandLimits | None = None) -> None:
        super().__init__(model, dt, limits)
        self.gains = gains
        check_zeta0(gains.zeta0, self.model)
        self._lam = math.nan
        self._eps = 0.0
        self._nu = 0.0
        self._z = 0.0
        self._resets = 0

    def set_gains(self, gains: DPPCGains) -> None:
        """Swap gains at run time; the current funnel is kept (re-initialised only if it no longer fits)."""
        check_zeta0(gains.zeta0, self.model)
        self.gains = gains

    def set_model(self, model: MBWParams) -> None:
        """As :meth:`ModelBased.set_model`, the gains checked against the new model (Assumption 4.1)."""
        if hasattr(self, "gains"):
            check_zeta0(self.gains.zeta0, check_model(model))
        super().set_model(model)

    def _rescale(self, old: MBWParams, new: MBWParams) -> None:
        """The funnel λ (4.7) and the error integral are lengths in model units: same metres, new units."""
        c = old.y_scale / new.y_scale
        self._lam *= c
        self._z *= c

    def _on_reset(self, y0: float, u0: float, r0: float) -> None:
        g = self.gains
        e0 = (y0 - r0) / self._ys
        lam0 = g.lambda0 / self._ys
        # Step 0 (4.9): choose λ0 so that e0 lies inside the funnel (with the margin).
        need = max(e0 / (g.funnel_margin * g.h_upper), -e0 / (g.funnel_margin * g.h_lower))
        self._lam = max(lam0, need)
        self._eps = 0.5 * math.log((self._lam * g.h_lower + e0) / (self._lam * g.h_upper - e0))
        self._nu = 0.0
        self._z = 0.0

    def _law(self, r_k: float, y: float) -> float:
        g = self.gains
        ys, off = self._ys, self._off
        y_m = (y - off) / ys
        e_m = (y - self._r_prev) / ys
        r_m = (r_k - off) / ys
        r_u = abs(r_k - self._r_prev) / ys  # (4.3), on the model's output scale
        if g.ki > 0.0:
            zmax = g.lambda0 / ys  # the integral never asks for more than the initial funnel
            self._z = min(max(self._z + g.ki * e_m, -zmax), zmax)
        nu, lam, eps, lam_prev, reset = dppc_nu(
            self._p, y_m, e_m, r_m - self._z, r_u, self._u_prev / self._us, g.exact_rate, self._lam, g.lambda_inf / ys,
            g.omega, g.chi, g.h_lower, g.h_upper, g.funnel_margin, g.zeta0)
        if reset:
            self._resets += 1
        self._lam, self._eps, self._nu = lam, eps, nu
        return (self._p[7] * (self._u_prev / self._us) + nu) * self._us  # (4.12)

    def state(self) -> dict[str, float]:
        s = super().state()
        s.update(epsilon=self._eps, **{"lambda": self._lam * self._ys}, nu=self._nu * self._us,
                 integral=self._z * self._ys, funnel_resets=float(self._resets))
        return s
