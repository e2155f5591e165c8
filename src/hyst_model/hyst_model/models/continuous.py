"""Continuous-time differential-equation-based (DEB) hysteresis models, solved exactly for piecewise-linear inputs.

All four are Duhem models ẏ = f(y, u, sgn u̇)·u̇, i.e. rate-independent: in the input domain they read
dy/du = g(y, u, s) with s = sgn(u̇). For an input that is linear between samples (the natural continuous
interpretation of a sampled signal; refine the grid to approach a smooth input) each interval is an ODE in u with
constant s, and ch. 3.2 of the thesis gives the closed-form solutions used here:

* backlash-like (3.1):  ẏ = b u̇ − a|u̇| y + c|u̇| u   → y = (c/a) u + Ψ(u), Ψ from (3.2)–(3.3)
* Dahl (3.6):           ẏ = β u̇ − α|u̇| y            → (3.7)
* Bouc-Wen special case (3.9), n = 1, k = 1, ρ = 0:  ẏ = ξ u̇ − φ|u̇| y − γ u̇ |y|; linear in y on each side of
  y = 0, so the interval is split where y crosses zero and (3.7)-type exponentials are used on each piece.
* general Bouc-Wen (2.24)–(2.25): y = ρ k u + (1 − ρ) k w, ẇ = ξ u̇ − φ|u̇||w|^{n−1} w − γ u̇ |w|^n; for n ≠ 1 there
  is no closed form and each interval is integrated in u with classical RK4 on ``substeps`` sub-intervals
  (n = 1 uses the exact BW solution).

These serve as the references for the discrete models (e.g. discrete BW (3.19) vs continuous BW (3.9), Fig. 3.7).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["backlash_like", "dahl", "bw_special", "bw_general", "bw_bound"]


@njit(cache=True, nogil=True)
def _lin_exact(y0: float, du: float, lam: float, a0: float, a1: float, u0: float) -> float:
    """Solve dy/du = a0 + a1 u − lam·y over [u0, u0 + du] exactly (lam may be 0)."""
    if abs(lam) < 1e-300:
        return y0 + a0 * du + a1 * (u0 * du + 0.5 * du * du)
    # particular solution y_p(u) = A + B u with B = a1/lam, A = (a0 − B)/lam
    B = a1 / lam
    A = (a0 - B) / lam
    e = math.exp(-lam * du)
    return A + B * (u0 + du) + (y0 - A - B * u0) * e


@njit(cache=True, nogil=True)
def backlash_like(a: float, b: float, c: float, u: np.ndarray, y0: float = 0.0) -> np.ndarray:
    """Backlash-like model (3.1) for a piecewise-linear input; exact per interval ((3.2)–(3.3)).

    On an interval with s = sgn(u̇): dy/du = b + c s u − a s y.
    """
    n = u.shape[0]
    y = np.empty(n)
    yk = y0
    y[0] = yk
    for k in range(1, n):
        du = u[k] - u[k - 1]
        if du != 0.0:
            s = 1.0 if du > 0 else -1.0
            yk = _lin_exact(yk, du, a * s, b, c * s, u[k - 1])
        y[k] = yk
    return y


@njit(cache=True, nogil=True)
def dahl(alpha: float, beta: float, u: np.ndarray, y0: float = 0.0) -> np.ndarray:
    """Dahl model (3.6), r = 1, for a piecewise-linear input; exact per interval (3.7).

    dy/du = β − α·s·y: the backlash-like law (3.1) without its c·s·u term, so the same interval solution serves.
    """
    return backlash_like(alpha, beta, 0.0, u, y0)


@njit(cache=True, nogil=True)
def _bw_interval(xi: float, phi: float, gamma: float, y0: float, u0: float, du: float) -> float:
    """Exact (3.9) over one linear input interval, splitting where y changes sign."""
    s = 1.0 if du > 0 else -1.0
    rem = du
    y = y0
    for _ in range(4):  # y can cross zero at most twice on a monotone interval; guard the loop anyway
        if rem == 0.0:
            break
        sy = 1.0 if y > 0 else (-1.0 if y < 0 else (1.0 if xi * s > 0 else -1.0))
        lam = phi * s + gamma * sy
        y_end = _lin_exact(y, rem, lam, xi, 0.0, u0)
        if y_end * sy >= 0.0:
            return y_end
        # zero crossing at u0 + d: y_p + (y − y_p) e^{−lam d} = 0 with y_p = xi/lam (or linear if lam = 0)
        if abs(lam) < 1e-300:
            d = -y / xi
        else:
            yp = xi / lam
            d = -math.log(yp / (yp - y)) / lam
        if not (d * rem > 0 and abs(d) < abs(rem)):
            return y_end
        u0 += d
        rem -= d
        y = 0.0
    return y


@njit(cache=True, nogil=True)
def bw_special(xi: float, phi: float, gamma: float, u: np.ndarray, y0: float = 0.0) -> np.ndarray:
    """Special-case Bouc-Wen (3.9) for a piecewise-linear input, exact per interval."""
    n = u.shape[0]
    y = np.empty(n)
    yk = y0
    y[0] = yk
    for k in range(1, n):
        du = u[k] - u[k - 1]
        if du != 0.0:
            yk = _bw_interval(xi, phi, gamma, yk, u[k - 1], du)
        y[k] = yk
    return y


@njit(cache=True, nogil=True)
def _bw_w_rhs(xi: float, phi: float, gamma: float, nexp: float, s: float, w: float) -> float:
    aw = abs(w)
    return xi - phi * s * aw ** (nexp - 1.0) * w - gamma * aw ** nexp


@njit(cache=True, nogil=True)
def _bw_general_w(xi, phi, gamma, nexp, u, w0, substeps):
    n = u.shape[0]
    w = np.empty(n)
    wk = w0
    w[0] = wk
    for k in range(1, n):
        du = u[k] - u[k - 1]
        if du != 0.0:
            s = 1.0 if du > 0 else -1.0
            h = du / substeps
            for _ in range(substeps):  # RK4 in the input domain: dw/du = g(w, s)
                k1 = _bw_w_rhs(xi, phi, gamma, nexp, s, wk)
                k2 = _bw_w_rhs(xi, phi, gamma, nexp, s, wk + 0.5 * h * k1)
                k3 = _bw_w_rhs(xi, phi, gamma, nexp, s, wk + 0.5 * h * k2)
                k4 = _bw_w_rhs(xi, phi, gamma, nexp, s, wk + h * k3)
                wk += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
        w[k] = wk
    return w


def bw_general(rho: float, k: float, xi: float, phi: float, gamma: float, n: float, u: np.ndarray,
               w0: float = 0.0, substeps: int = 8) -> np.ndarray:
    """General Bouc-Wen (2.24)–(2.25): y = ρ k u + (1 − ρ) k w.

    Parameters
    ----------
    rho : float
        Weight 0 < ρ ≤ 1 (ρ = 0 is allowed and gives the pure hysteretic part).
    k : float
        Stiffness coefficient.
    xi, phi, gamma : float
        Shape parameters of (2.25).
    n : float
        Exponent n ≥ 1; n = 1 is solved exactly.
    u : ndarray
        Input samples, linear in between.
    w0 : float
        Initial hysteretic state.
    substeps : int
        RK4 sub-intervals per input interval when n ≠ 1.
    """
    if n < 1:
        raise ValueError("Bouc-Wen exponent n must be >= 1")
    u = np.ascontiguousarray(u, dtype=np.float64)
    if n == 1.0:
        w = bw_special(xi, phi, gamma, u, w0)
    else:
        w = _bw_general_w(xi, phi, gamma, float(n), u, float(w0), int(substeps))
    return rho * k * u + (1.0 - rho) * k * w


def bw_bound(xi: float, phi: float, gamma: float) -> float:
    """Bound (3.10) on |y| of (3.9): ξ/(φ + γ), valid when φ + γ > 0 (and |y0| within it); inf otherwise."""
    return xi / (phi + gamma) if phi + gamma > 0 else math.inf
