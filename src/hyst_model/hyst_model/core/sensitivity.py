"""Forward parameter sensitivities of the MBW recursion (3.21), for exact Jacobians in output-error fitting.

Differentiating (3.21) with respect to θ = (ζ1, ζ2, ψ1, ψ2, α1, α2, δ1, δ2) gives the linear recursion

.. math::

    S_k = \\frac{\\partial f}{\\partial y_{k-1}} S_{k-1} + \\frac{\\partial f}{\\partial \\theta}, \\qquad
    \\frac{\\partial f}{\\partial y_{k-1}} = \\delta_1 - (\\psi_1 + \\psi_2 v)|\\nu| - (\\alpha_1 + \\alpha_2 v)\\,\\nu\\,
    \\mathrm{sgn}(y_{k-1})

with ∂ν/∂δ2 = −u_{k−1}. It runs alongside the recursion in the same loop (numba), so a full Jacobian costs about
two simulations instead of nine. The start from rest (:func:`hyst_model.core.mbw.mbw_rest_state`) is
differentiated the same way by iterating the recursion and its sensitivity on the held input.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .mbw import mbw_step

__all__ = ["mbw_simulate_sens", "mbw_rest_state_sens"]


@njit(cache=True)
def _sens_step(p, yp, u, up, S_prev, S_out):
    nu = u - p[7] * up
    v = abs(u - up)
    anu = abs(nu)
    ay = abs(yp)
    sy = 1.0 if yp > 0 else (-1.0 if yp < 0 else 0.0)
    snu = 1.0 if nu > 0 else (-1.0 if nu < 0 else 0.0)
    a = p[4] + p[5] * v
    b = p[2] + p[3] * v
    dfdy = p[6] - b * anu - a * nu * sy
    dfdnu = (p[0] + p[1] * v) - b * snu * yp - a * ay
    S_out[0] = dfdy * S_prev[0] + nu
    S_out[1] = dfdy * S_prev[1] + v * nu
    S_out[2] = dfdy * S_prev[2] - anu * yp
    S_out[3] = dfdy * S_prev[3] - v * anu * yp
    S_out[4] = dfdy * S_prev[4] - nu * ay
    S_out[5] = dfdy * S_prev[5] - v * nu * ay
    S_out[6] = dfdy * S_prev[6] + yp
    S_out[7] = dfdy * S_prev[7] - dfdnu * up


@njit(cache=True)
def mbw_rest_state_sens(p: np.ndarray, u0: float, max_steps: int = 200000, tol: float = 1e-13):
    """Rest state (see :func:`mbw_rest_state`) and its gradient with respect to the 8 parameters."""
    y = 0.0
    S = np.zeros(8)
    S2 = np.zeros(8)
    for _ in range(max_steps):
        y_new = mbw_step(p, y, u0, u0)
        _sens_step(p, y, u0, u0, S, S2)
        S[:] = S2
        if not np.isfinite(y_new):
            return y_new, S
        if abs(y_new - y) <= tol * (1.0 + abs(y_new)):
            return y_new, S
        y = y_new
    return y, S


@njit(cache=True)
def mbw_simulate_sens(p: np.ndarray, u: np.ndarray, y0: float, S0: np.ndarray):
    """Simulate (3.21) from state ``y0`` (with gradient ``S0``) and return ``(y, S)``, S of shape (n, 8).

    ``u_{-1} = u[0]`` as in :func:`hyst_model.core.mbw.mbw_simulate`.
    """
    n = u.shape[0]
    y = np.empty(n)
    S = np.empty((n, 8))
    Sp = S0.copy()
    Sk = np.empty(8)
    yp = y0
    up = u[0] if n else 0.0
    for k in range(n):
        yk = mbw_step(p, yp, u[k], up)
        _sens_step(p, yp, u[k], up, Sp, Sk)
        y[k] = yk
        S[k, :] = Sk
        Sp[:] = Sk
        yp = yk
        up = u[k]
    return y, S
