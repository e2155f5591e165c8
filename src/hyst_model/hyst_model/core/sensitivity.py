"""Forward parameter sensitivities of the MBW recursion (3.21), for exact Jacobians in output-error fitting.

Differentiating (3.21) with respect to θ = (ζ1, ζ2, ψ1, ψ2, α1, α2, δ1, δ2) gives the linear recursion

.. math::

    S_k = \\frac{\\partial f}{\\partial y_{k-1}} S_{k-1} + \\frac{\\partial f}{\\partial \\theta}, \\qquad
    \\frac{\\partial f}{\\partial y_{k-1}} = \\delta_1 - (\\psi_1 + \\psi_2 v)|\\nu|
    - (\\alpha_1 + \\alpha_2 v)\\,\\nu\\,
    \\mathrm{sgn}(y_{k-1})

with ∂ν/∂δ2 = −u_{k−1}. It runs alongside the recursion in the same loop (numba), so a full Jacobian costs about
two simulations instead of nine. The start from rest (:func:`hyst_model.core.mbw.mbw_rest_state`, closed form)
is differentiated analytically.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .mbw import mbw_step

__all__ = ["mbw_simulate_sens", "mbw_simulate_jac", "mbw_rest_state_sens", "mbw_normal_equations"]


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def mbw_rest_state_sens(p: np.ndarray, u0: float, max_steps: int = 200000, tol: float = 1e-13):
    """Rest state (closed form, see :func:`hyst_model.core.mbw.mbw_rest_state`) and its gradient (8,)."""
    S = np.zeros(8)
    nu = (1.0 - p[7]) * u0
    b = p[0] * nu
    if nu == 0.0 or b == 0.0:
        # y* = 0 for every nearby θ except through ζ1·ν: dy*/dζ1 = ν/den is still defined when only ζ1 = 0
        return 0.0, S
    s = 1.0 if b > 0 else -1.0
    snu = 1.0 if nu > 0 else -1.0
    den = 1.0 - p[6] + p[2] * abs(nu) + p[4] * nu * s
    if not (0.0 < den < 2.0):
        return np.nan, S
    y = b / den
    S[0] = nu / den
    S[2] = -y * abs(nu) / den
    S[4] = -y * nu * s / den
    S[6] = y / den
    dy_dnu = p[0] / den - y / den * (p[2] * snu + p[4] * s)
    S[7] = -u0 * dy_dnu
    return y, S


@njit(cache=True, nogil=True)
def mbw_simulate_jac(p: np.ndarray, u: np.ndarray, y0: float, S0: np.ndarray, cols: np.ndarray,
                     y_scale: float, offset: float):
    """:func:`mbw_simulate_sens` written straight into the model's Jacobian layout: ``(y_scale·y + offset, J)``
    with ``J[:, i] = y_scale·S[:, cols[i]]`` and a last column of ones (the offset).

    One pass and one (n, len(cols) + 1) array: gathering the columns afterwards in numpy cost four times the
    recursion itself on 60k samples.
    """
    n = u.shape[0]
    m = cols.shape[0]
    y = np.empty(n)
    J = np.empty((n, m + 1))
    Sp = S0.copy()
    Sk = np.empty(8)
    yp = y0
    up = u[0] if n else 0.0
    for k in range(n):
        yk = mbw_step(p, yp, u[k], up)
        _sens_step(p, yp, u[k], up, Sp, Sk)
        y[k] = y_scale * yk + offset
        for i in range(m):
            J[k, i] = y_scale * Sk[cols[i]]
        J[k, m] = 1.0
        Sp[:] = Sk
        yp = yk
        up = u[k]
    return y, J


def mbw_simulate_sens(p: np.ndarray, u: np.ndarray, y0: float, S0: np.ndarray):
    """Simulate (3.21) from state ``y0`` (with gradient ``S0``) and return ``(y, S)``, S of shape (n, 8).

    ``u_{-1} = u[0]`` as in :func:`hyst_model.core.mbw.mbw_simulate`. (:func:`mbw_simulate_jac` with every
    parameter, unit scale and no offset.)
    """
    y, J = mbw_simulate_jac(p, u, y0, S0, _ALL8, 1.0, 0.0)
    return y, J[:, :8]


_ALL8 = np.arange(8)


@njit(cache=True, nogil=True)
def mbw_normal_equations(p: np.ndarray, un: np.ndarray, y0: float, S0: np.ndarray, cols: np.ndarray,
                         y_scale: float, offset: float, a: int, target: np.ndarray, inv_scale: float):
    """Gauss-Newton normal equations of the free-run output error, fused into one pass over the record.

    Residual r_k = (y_scale·y_k + offset − target_{k−a})·inv_scale for k ≥ a; parameters are the recursion
    parameters listed in ``cols`` (indices into the 8) followed by the offset. Returns ``(H, g, rr)`` with
    H = JᵀJ, g = Jᵀr, rr = rᵀr (inf when the simulation diverges) without storing the n × p Jacobian.
    """
    n = un.shape[0]
    m = cols.shape[0]
    p_all = m + 1
    H = np.zeros((p_all, p_all))
    g = np.zeros(p_all)
    jrow = np.empty(p_all)
    Sp = S0.copy()
    Sk = np.empty(8)
    yp = y0
    up = un[0] if n else 0.0
    rr = 0.0
    for k in range(n):
        yk = mbw_step(p, yp, un[k], up)
        _sens_step(p, yp, un[k], up, Sp, Sk)
        Sp[:] = Sk
        yp = yk
        up = un[k]
        if k < a:
            continue
        tk = target[k - a]
        if tk != tk:  # NaN target: a held-out sample (interleaved validation), simulated but not scored
            if not np.isfinite(yk):
                return H, g, np.inf
            continue
        r = (y_scale * yk + offset - tk) * inv_scale
        if not np.isfinite(r):
            return H, g, np.inf
        rr += r * r
        for i in range(m):
            jrow[i] = y_scale * inv_scale * Sk[cols[i]]
        jrow[m] = inv_scale
        for i in range(p_all):
            g[i] += jrow[i] * r
            Hi = H[i]
            for j in range(p_all):  # the full row (vectorises); j < i is overwritten below, j ≥ i sums as before
                Hi[j] += jrow[i] * jrow[j]
    for i in range(p_all):
        for j in range(i):
            H[i, j] = H[j, i]
    if not np.all(np.isfinite(H)):
        return H, g, np.inf
    return H, g, rr
