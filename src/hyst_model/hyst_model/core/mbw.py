"""The one Modified Bouc-Wen (MBW) recursion of hyst, compiled with numba.

Every user of the model — simulation, identification, the simulated plant and the controllers — calls the
functions here, so there is exactly one implementation of thesis eq. (3.21):

.. math::

    y_k = \\delta_1 y_{k-1} + (\\zeta_1 + \\zeta_2 v_{u,k})\\nu_k - (\\psi_1 + \\psi_2 v_{u,k})|\\nu_k| y_{k-1}
          - (\\alpha_1 + \\alpha_2 v_{u,k})\\nu_k |y_{k-1}|

with :math:`v_{u,k} = |u_k - u_{k-1}|` (3.20). The discrete Bouc-Wen model (3.19) is the special case
:math:`\\zeta_2 = \\psi_2 = \\alpha_2 = 0`.

The ν convention
----------------
(3.18) writes :math:`\\nu_k = (u_k - \\delta_2 u_{k-1})/\\Delta t` with :math:`\\zeta = \\Delta t\\,\\xi`,
:math:`\\psi = \\Delta t\\,\\varphi`, :math:`\\alpha = \\Delta t\\,\\gamma`. The parameter values the thesis uses
(Fig. 3.7, Fig. 3.8, Table 4.1) only give bounded loops when one sample is the time unit, so hyst uses

.. math::  \\nu_k = u_k - \\delta_2 u_{k-1}

(Δt absorbed). The control laws (4.12) and (5.23) then read :math:`u_k = \\delta_2 u_{k-1} + \\nu_k`.
A continuous-time parameter set (ξ, φ, γ) maps to this convention unchanged — ζ = ξ, ψ = φ, α = γ, no Δt
factor: (3.18)'s Δt in ζ = Δt·ξ cancels the 1/Δt in its ν, since (3.17) is Δt·ξ·(Δu/Δt) = ξ·Δu; see
:func:`hyst_model.core.params.from_continuous`.

Units
-----
The recursion is unit-free; the thesis parameters live on a normalised input scale. :class:`MBWParams` carries
an explicit input scale ``u_scale`` (V per model unit), output scale ``y_scale`` (m per model unit) and output
``offset`` (m), so that ``u_model = u / u_scale`` and ``y = y_scale * y_model + offset`` at every boundary
(scaling u is exact; ν and v_u scale with it).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = [
    "PARAM_NAMES",
    "mbw_step",
    "mbw_simulate",
    "mbw_simulate_batch",
    "mbw_rest_state",
]

#: Order of the eight recursion parameters in every packed parameter vector.
PARAM_NAMES: tuple[str, ...] = ("zeta1", "zeta2", "psi1", "psi2", "alpha1", "alpha2", "delta1", "delta2")


@njit(cache=True, nogil=True, fastmath=False)
def mbw_step(p: np.ndarray, y_prev: float, u: float, u_prev: float) -> float:
    """One step of the MBW recursion (3.21) in model units.

    Parameters
    ----------
    p : ndarray, shape (8,)
        ``(zeta1, zeta2, psi1, psi2, alpha1, alpha2, delta1, delta2)``.
    y_prev : float
        Output at k-1 (model units).
    u, u_prev : float
        Input at k and k-1 (model units).

    Returns
    -------
    float
        y_k.
    """
    nu = u - p[7] * u_prev
    v = abs(u - u_prev)
    return (p[6] * y_prev + (p[0] + p[1] * v) * nu
            - (p[2] + p[3] * v) * abs(nu) * y_prev
            - (p[4] + p[5] * v) * nu * abs(y_prev))


@njit(cache=True, nogil=True)
def mbw_rest_state(p: np.ndarray, u0: float, max_steps: int = 200000, tol: float = 1e-13) -> float:
    r"""Output the recursion settles to when the input has been held at ``u0`` for a long time.

    At constant input v = 0 and ν = (1 − δ2)·u0, so (3.21) is the affine map y ← a·y + ζ1·ν with
    a = δ1 − ψ1|ν| − α1·ν·sgn(y). Started from y = 0 the state takes the sign s of ζ1·ν at once and converges
    (for |a| < 1) to the fixed point

    .. math::  y^* = \frac{\zeta_1 \nu}{1 - \delta_1 + \psi_1 |\nu| + \alpha_1 \nu s},

    returned in closed form (the iteration it replaces needed ~10⁴ steps for δ1 ≈ 1). ν = 0 (δ2 = 1 or u0 = 0)
    gives 0. A map that does not contract (|a| ≥ 1) has no rest state: NaN, which callers treat as divergence.
    ``max_steps`` and ``tol`` are kept for signature compatibility and unused.
    """
    nu = (1.0 - p[7]) * u0
    if nu == 0.0:
        return 0.0
    b = p[0] * nu
    if b == 0.0:
        return 0.0
    s = 1.0 if b > 0 else -1.0
    den = 1.0 - p[6] + p[2] * abs(nu) + p[4] * nu * s
    if not (0.0 < den < 2.0):
        return np.nan
    return b / den


@njit(cache=True, nogil=True)
def mbw_simulate(p: np.ndarray, u: np.ndarray, y0: float = 0.0, u_prev: float = np.nan) -> np.ndarray:
    """Run the MBW recursion (3.21) over a whole input record (model units).

    Parameters
    ----------
    p : ndarray, shape (8,)
        Packed parameters, see :data:`PARAM_NAMES`.
    u : ndarray, shape (n,)
        Input in model units.
    y0 : float
        State before the first sample (y_{-1}).
    u_prev : float
        Input before the first sample (u_{-1}); NaN means ``u[0]`` (no artificial step at k = 0).

    Returns
    -------
    ndarray, shape (n,)
        Output in model units. Divergence shows up as inf/NaN and is left to the caller to judge.
    """
    n = u.shape[0]
    y = np.empty(n)
    up = u[0] if np.isnan(u_prev) else u_prev
    yp = y0
    for k in range(n):
        yk = mbw_step(p, yp, u[k], up)
        y[k] = yk
        yp = yk
        up = u[k]
    return y


@njit(cache=True, nogil=True, parallel=True)
def mbw_simulate_batch(P: np.ndarray, u: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """Simulate many parameter sets on one input at once (swarms, multi-start), in parallel.

    Parameters
    ----------
    P : ndarray, shape (m, 8)
        One packed parameter vector per row.
    u : ndarray, shape (n,)
        Input in model units (u_{-1} = u[0]).
    y0 : ndarray, shape (m,)
        Initial state per row.

    Returns
    -------
    ndarray, shape (m, n)
    """
    m = P.shape[0]
    n = u.shape[0]
    Y = np.empty((m, n))
    for i in prange(m):
        p = P[i]
        yp = y0[i]
        up = u[0]
        for k in range(n):
            yk = mbw_step(p, yp, u[k], up)
            Y[i, k] = yk
            yp = yk
            up = u[k]
    return Y
