"""The model protocol every fitted model follows (base hysteresis models and base + effects).

A model is a parametric map from a sampled input record to an output record, both in SI units. Its parameters
are named, each with bounds and a default, in one place (:meth:`Model.params`); estimators work on the packed
vector θ in that order. Non-fitted configuration (input/output normalisation, sample time) is constructor state.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from .core.mbw import PARAM_NAMES
from .core.params import BOUNDS, MBWParams

__all__ = ["Param", "Model", "MBWModel"]


@dataclass(frozen=True)
class Param:
    """One named model parameter with its bounds.

    Attributes
    ----------
    name : str
        Unique within a model (effects prefix theirs, e.g. ``creep.gain``).
    default : float
        Starting value for identification.
    lower, upper : float
        Bounds used by every estimator.
    unit : str
        SI unit, or "" for dimensionless.
    doc : str
        One line a lab user understands.
    """

    name: str
    default: float
    lower: float
    upper: float
    unit: str = ""
    doc: str = ""


class Model(ABC):
    """A SISO model y = M(θ; t, u) in SI units (t in s, u in V, y in m)."""

    #: Short name used on the command line and in params files ("mbw", "bw", ...).
    name: str = "model"

    @abstractmethod
    def params(self) -> tuple[Param, ...]:
        """Named parameters with bounds, in packed-vector order."""

    @abstractmethod
    def simulate(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Free-run (simulation-mode) output in metres for packed parameters ``theta``."""

    # Conveniences shared by all models -------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params())

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        ps = self.params()
        return np.array([p.lower for p in ps]), np.array([p.upper for p in ps])

    @property
    def theta0(self) -> np.ndarray:
        return np.array([p.default for p in self.params()])

    def pack(self, values: dict[str, float]) -> np.ndarray:
        """Packed vector from a name→value mapping (missing names take their default)."""
        return np.array([float(values.get(p.name, p.default)) for p in self.params()])

    def unpack(self, theta: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, theta)}

    def config(self) -> dict[str, float | str]:
        """Non-fitted configuration that a params file must carry to rebuild this model."""
        return {}


class MBWModel(Model):
    """The Modified Bouc-Wen model (3.21) in SI units, or the discrete BW (3.19) with ``rate=False``.

    Fitted parameters: the eight recursion parameters (bounds :data:`hyst_model.core.params.BOUNDS`, the rate
    terms ζ2, ψ2, α2 absent for BW) and the output offset in metres. ``u_scale`` (V per model unit) and
    ``y_scale`` (m per model unit) are fixed normalisations chosen from the data so that the thesis's bounds
    apply (scaling y by c equals scaling ζ1, ζ2 by c; scaling u is exact).

    Besides the protocol it offers the exact Jacobian (:meth:`simulate_jac`) and fused Gauss-Newton normal
    equations (:meth:`normal_equations`) from forward sensitivities, which :mod:`hyst_model.identify` uses.
    """

    def __init__(self, u_scale: float = 1.0, y_scale: float = 1.0, rate: bool = True,
                 offset_bound: float = 1e-3):
        if not (u_scale > 0 and y_scale > 0):
            raise ValueError("u_scale and y_scale must be positive")
        self.u_scale = float(u_scale)
        self.y_scale = float(y_scale)
        self.offset_bound = float(offset_bound)
        self.rate = bool(rate)
        self.name = "mbw" if rate else "bw"
        defaults = dict(zip(PARAM_NAMES, (0.4, 1e-3, 0.03, 0.0, -0.04, 0.0, 0.98, 0.98)))
        ps = []
        for n in PARAM_NAMES:
            if not rate and n in ("zeta2", "psi2", "alpha2"):
                continue
            lo, hi = BOUNDS[n]
            ps.append(Param(n, defaults[n], lo, hi, "", f"MBW {n} (3.21)"))
        ps.append(Param("offset", 0.0, -offset_bound, offset_bound, "m", "sensor reading at rest at 0 V"))
        self._params = tuple(ps)
        # columns of the 8 recursion sensitivities that are fitted parameters here (BW drops the rate terms)
        self._cols = np.array([PARAM_NAMES.index(p.name) for p in ps if p.name in PARAM_NAMES])

    def params(self) -> tuple[Param, ...]:
        return self._params

    def to_params(self, theta: np.ndarray) -> MBWParams:
        """The :class:`MBWParams` (with this model's scaling) for packed ``theta``."""
        d = dict(zip(PARAM_NAMES, (0.0,) * 8))
        d.update(self.unpack(theta))
        off = d.pop("offset")
        return MBWParams(**d, u_scale=self.u_scale, y_scale=self.y_scale, offset=off)

    def simulate(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.to_params(theta).simulate(u)

    def simulate_jac(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output (m) and its exact Jacobian d y / d theta, shape (n, len(theta)), from rest.

        Uses the forward sensitivities of :mod:`hyst_model.core.sensitivity` (about two simulations' cost).
        """
        from .core.sensitivity import mbw_rest_state_sens, mbw_simulate_jac
        p = self.to_params(theta)
        pv = p.vector
        un = np.ascontiguousarray(np.asarray(u, dtype=np.float64) / self.u_scale)
        if un.size:
            y0, S0 = mbw_rest_state_sens(pv, un[0])
        else:
            y0, S0 = 0.0, np.zeros(8)
        return mbw_simulate_jac(pv, un, y0, S0, self._cols, self.y_scale, p.offset)

    def normal_equations(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray, a: int, y: np.ndarray,
                         scale: float) -> tuple[np.ndarray, np.ndarray, float]:
        """JᵀJ, Jᵀr, rᵀr of the residual (simulate(θ)[a:] − y)/scale in one fused pass (for Gauss-Newton/LM)."""
        from .core.sensitivity import mbw_normal_equations, mbw_rest_state_sens
        p = self.to_params(theta)
        pv = p.vector
        un = np.ascontiguousarray(np.asarray(u, dtype=np.float64) / self.u_scale)
        y0, S0 = mbw_rest_state_sens(pv, un[0]) if un.size else (0.0, np.zeros(8))
        if not np.isfinite(y0):
            return np.zeros((len(self._params),) * 2), np.zeros(len(self._params)), np.inf
        return mbw_normal_equations(pv, un, y0, S0, self._cols, self.y_scale, p.offset, int(a),
                                    np.ascontiguousarray(y, dtype=np.float64), 1.0 / scale)

    def config(self) -> dict[str, float | str]:
        return {"u_scale": self.u_scale, "y_scale": self.y_scale, "offset_bound": self.offset_bound}
