"""Prandtl-Ishlinskii (PI) model (2.13) with play operators, and its analytic inverse (Krejčí & Kuhnen 2001).

.. math::  y_k = p_0 u_k + \\sum_{j=1}^{M} p_j F_{r_j}[u]_k, \\qquad
           F_r[u]_k = \\max(u_k - r, \\min(u_k + r, F_r[u]_{k-1}))

with initial state F_r[u]_{-1} = 0 (so F_r[u]_0 = max(u_0 − r, min(u_0 + r, 0)), the condition below (2.11)).
The model is linear in the weights (the thesis's remark after (2.13)), and it is analytically invertible: the
inverse of a PI model with thresholds 0 < r_1 < ... < r_M is again a PI model with

.. math::

    p'_0 = 1/p_0, \\quad p'_i = -\\frac{p_i}{(p_0 + \\sum_{j\\le i} p_j)(p_0 + \\sum_{j<i} p_j)}, \\quad
    r'_i = p_0 r_i + \\sum_{j<i} p_j (r_i - r_j),

valid when every partial sum p_0 + Σ_{j≤i} p_j is positive. This is the comparison family the literature uses for
feedforward compensation; :class:`PIModel` exposes it through the :class:`~hyst_model.model.Model` protocol.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..model import Model, Param

__all__ = ["play_operators", "pi_simulate", "pi_inverse", "PIModel"]


@njit(cache=True, nogil=True)
def play_operators(u: np.ndarray, r: np.ndarray, z0: np.ndarray) -> np.ndarray:
    """Outputs of the play operators F_{r_j}[u] (2.11), shape (n, M), starting from states ``z0``."""
    n = u.shape[0]
    m = r.shape[0]
    Z = np.empty((n, m))
    z = z0.copy()
    for k in range(n):
        for j in range(m):
            z[j] = max(u[k] - r[j], min(u[k] + r[j], z[j]))
            Z[k, j] = z[j]
    return Z


def pi_simulate(p0: float, p: np.ndarray, r: np.ndarray, u: np.ndarray, z0: np.ndarray | None = None) -> np.ndarray:
    """PI model output (2.13)."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    r = np.ascontiguousarray(r, dtype=np.float64)
    z0 = np.zeros(r.size) if z0 is None else np.asarray(z0, dtype=np.float64)
    return p0 * u + play_operators(u, r, z0) @ np.asarray(p, dtype=np.float64)


def pi_inverse(p0: float, p: np.ndarray, r: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Weights and thresholds ``(p0', p', r')`` of the inverse PI model (zero initial states map to zero).

    Raises
    ------
    ValueError
        Thresholds not strictly increasing and positive, or a partial weight sum not positive (not invertible).
    """
    p = np.asarray(p, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    if p0 <= 0:
        raise ValueError("PI model with p0 <= 0 is not invertible")
    if r.size and (r[0] <= 0 or np.any(np.diff(r) <= 0)):
        raise ValueError("PI thresholds must be positive and strictly increasing")
    csum = p0 + np.cumsum(p)
    if np.any(csum <= 0):
        raise ValueError("PI model not invertible: a partial weight sum p0 + p1 + ... + pi is not positive")
    prev = np.concatenate(([p0], csum[:-1]))
    pinv = -p / (csum * prev)
    rinv = np.array([p0 * r[i] + np.sum(p[:i] * (r[i] - r[:i])) for i in range(r.size)])
    return 1.0 / p0, pinv, rinv


class PIModel(Model):
    """PI model (2.13) on ``n_play`` equally spaced thresholds r_j = j·r_max/n_play, plus an output offset.

    Parameters
    ----------
    n_play : int
        Number of play operators M.
    r_max : float
        Largest threshold (V); half the input range is a good choice.
    u_scale, y_scale : float
        Input (V) and output (m) normalisation: the weights act on u/u_scale and give y/y_scale, so their bounds
        and defaults do not depend on the actuator (see :func:`hyst_model.models.data_config`).
    """

    name = "pi"

    def __init__(self, n_play: int = 10, r_max: float = 1.0, y_scale: float = 1.0, offset_bound: float = 1e-3,
                 u_scale: float = 1.0):
        if n_play < 1 or r_max <= 0 or y_scale <= 0 or u_scale <= 0:
            raise ValueError("PI model needs n_play >= 1, r_max > 0, u_scale > 0, y_scale > 0")
        self.u_scale = float(u_scale)
        self.n_play = int(n_play)
        self.r_max = float(r_max)
        self.y_scale = float(y_scale)
        self.offset_bound = float(offset_bound)
        self.r = self.r_max * np.arange(1, self.n_play + 1) / self.n_play
        ps = [Param("p0", 1.0, 0.0, 100.0, "", "linear (r = 0) weight")]
        ps += [Param(f"p{j}", 0.0, -100.0, 100.0, "", f"play weight at r = {self.r[j - 1]:.4g} V")
               for j in range(1, self.n_play + 1)]
        ps.append(Param("offset", 0.0, -self.offset_bound, self.offset_bound, "m", "sensor reading at rest at 0 V"))
        self._params = tuple(ps)

    def params(self) -> tuple[Param, ...]:
        return self._params

    def simulate(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=np.float64)
        un = np.asarray(u, dtype=np.float64) / self.u_scale
        return self.y_scale * pi_simulate(theta[0], theta[1:-1], self.r / self.u_scale, un) + theta[-1]

    def inverse(self, theta: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Input (V) that makes the model output ``y`` (m): the analytic inverse PI applied to (y − offset)."""
        theta = np.asarray(theta, dtype=np.float64)
        q0, q, rr = pi_inverse(theta[0], theta[1:-1], self.r / self.u_scale)
        return self.u_scale * pi_simulate(q0, q, rr, (np.asarray(y, dtype=np.float64) - theta[-1]) / self.y_scale)

    def config(self) -> dict[str, float | str]:
        return {"n_play": float(self.n_play), "r_max": self.r_max, "u_scale": self.u_scale, "y_scale": self.y_scale,
                "offset_bound": self.offset_bound}
