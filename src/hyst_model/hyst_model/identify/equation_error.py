"""The equation-error starts of the fast method (:class:`~hyst_model.identify.fast.FastFit`).

Given the measured output, MBW (3.21) is *linear* in (ζ1, ζ2, ψ1, ψ2, α1, α2) for fixed δ1, δ2 and offset c, and δ1
enters linearly as well, so a grid over δ2 (:data:`DELTA2_GRID`) and a dense grid of offsets costs one small
bounded least-squares solve each (compiled normal equations, :func:`_ee_normal_scan`); every candidate is then
simulated in free run at once (:func:`hyst_model.core.mbw.mbw_simulate_batch`) and ranked by its free-run error
(:func:`equation_error_starts`). The regression runs on the output and on a zero-phase low-passed copy
(differencing amplifies sensor noise; low-passing removes the sample-to-sample response of fast memory).
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.optimize import lsq_linear
from scipy.signal import butter, sosfiltfilt

from ..core.mbw import PARAM_NAMES, mbw_rest_state, mbw_simulate_batch
from ..model import MBWModel

__all__ = ["equation_error_starts", "DELTA2_GRID"]

#: δ2 grid for the equation-error stage (δ ≈ 1 − Δt/τ; see the thesis README on relaxation). δ1 is regressed.
DELTA2_GRID = 1.0 - np.array([0.0, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 0.01, 0.02, 0.03, 0.04, 0.05, 0.07, 0.1,
                              0.15, 0.2, 0.3, 0.5])


@njit(cache=True, nogil=True)
def _ee_normal(Y0, Y1, u0, u1, c, d2, ys, rate):
    """Normal equations of the equation-error regression (3.21) for one (δ2, offset), without forming X."""
    p = 7 if rate else 4
    G = np.zeros((p, p))
    b = np.zeros(p)
    x = np.empty(p)
    yy = 0.0
    for k in range(Y0.shape[0]):
        yp = (Y0[k] - c) / ys
        yk = (Y1[k] - c) / ys
        nu = u1[k] - d2 * u0[k]
        v = abs(u1[k] - u0[k])
        anu = abs(nu)
        ayp = abs(yp)
        if rate:
            x[0] = yp
            x[1] = nu
            x[2] = v * nu
            x[3] = -anu * yp
            x[4] = -v * anu * yp
            x[5] = -nu * ayp
            x[6] = -v * nu * ayp
        else:
            x[0] = yp
            x[1] = nu
            x[2] = -anu * yp
            x[3] = -nu * ayp
        yy += yk * yk
        for i in range(p):
            b[i] += x[i] * yk
            for j in range(i, p):
                G[i, j] += x[i] * x[j]
    for i in range(p):
        for j in range(i):
            G[i, j] = G[j, i]
    return G, b, yy


@njit(cache=True, nogil=True)
def _ee_normal_scan(Y0, Y1, u0, u1, cs, d2, ys, rate):
    """:func:`_ee_normal` at every offset of the ascending grid ``cs`` in one sweep.

    With γ = c/ys each regressor row is P + γQ, where P and Q depend on c only through s = sgn(y_{k−1} − c),
    which flips the sign of the two |y_{k−1}| columns. Sums over the rows below c (s = −1) are therefore the
    s = +1 sums with those columns' signs flipped, and the rows sorted by y_{k−1} give every c in O(n·p²) in all.
    """
    p = 7 if rate else 4
    n = Y0.shape[0]
    m = cs.shape[0]
    sgn = np.ones(p)
    sgn[p - 2 if rate else p - 1] = -1.0
    if rate:
        sgn[p - 1] = -1.0
    # [PP, PQ+QP, QQ] and [Pβ, Qβ − P, −Q] for the rows above (A) and below (B) c
    A2 = np.zeros((3, p, p))
    A1 = np.zeros((3, p))
    B2 = np.zeros((3, p, p))
    B1 = np.zeros((3, p))
    sb = 0.0
    sbb = 0.0
    P = np.empty((n, p))
    Q = np.empty((n, p))
    beta = np.empty(n)
    for k in range(n):
        a = Y0[k] / ys
        beta[k] = Y1[k] / ys
        nu = u1[k] - d2 * u0[k]
        v = abs(u1[k] - u0[k])
        anu = abs(nu)
        if rate:
            P[k, 0], Q[k, 0] = a, -1.0
            P[k, 1], Q[k, 1] = nu, 0.0
            P[k, 2], Q[k, 2] = v * nu, 0.0
            P[k, 3], Q[k, 3] = -anu * a, anu
            P[k, 4], Q[k, 4] = -v * anu * a, v * anu
            P[k, 5], Q[k, 5] = -nu * a, nu
            P[k, 6], Q[k, 6] = -v * nu * a, v * nu
        else:
            P[k, 0], Q[k, 0] = a, -1.0
            P[k, 1], Q[k, 1] = nu, 0.0
            P[k, 2], Q[k, 2] = -anu * a, anu
            P[k, 3], Q[k, 3] = -nu * a, nu
        sb += beta[k]
        sbb += beta[k] * beta[k]
        for i in range(p):
            A1[0, i] += P[k, i] * beta[k]
            A1[1, i] += Q[k, i] * beta[k] - P[k, i]
            A1[2, i] -= Q[k, i]
            for j in range(p):
                A2[0, i, j] += P[k, i] * P[k, j]
                A2[1, i, j] += P[k, i] * Q[k, j] + Q[k, i] * P[k, j]
                A2[2, i, j] += Q[k, i] * Q[k, j]
    order = np.argsort(Y0)
    G = np.empty((m, p, p))
    b = np.empty((m, p))
    yy = np.empty(m)
    r = 0
    for ic in range(m):
        c = cs[ic]
        while r < n and Y0[order[r]] < c:  # row moves from above c to below it
            k = order[r]
            for i in range(p):
                d1 = P[k, i] * beta[k]
                d2_ = Q[k, i] * beta[k] - P[k, i]
                d3 = -Q[k, i]
                A1[0, i] -= d1
                A1[1, i] -= d2_
                A1[2, i] -= d3
                B1[0, i] += d1
                B1[1, i] += d2_
                B1[2, i] += d3
                for j in range(p):
                    e1 = P[k, i] * P[k, j]
                    e2 = P[k, i] * Q[k, j] + Q[k, i] * P[k, j]
                    e3 = Q[k, i] * Q[k, j]
                    A2[0, i, j] -= e1
                    A2[1, i, j] -= e2
                    A2[2, i, j] -= e3
                    B2[0, i, j] += e1
                    B2[1, i, j] += e2
                    B2[2, i, j] += e3
            r += 1
        g = c / ys
        for i in range(p):
            b[ic, i] = (A1[0, i] + g * A1[1, i] + g * g * A1[2, i]
                        + sgn[i] * (B1[0, i] + g * B1[1, i] + g * g * B1[2, i]))
            for j in range(p):
                G[ic, i, j] = (A2[0, i, j] + g * A2[1, i, j] + g * g * A2[2, i, j]
                               + sgn[i] * sgn[j] * (B2[0, i, j] + g * B2[1, i, j] + g * g * B2[2, i, j]))
        yy[ic] = sbb - 2.0 * g * sb + n * g * g
    return G, b, yy


def _bounded_quadratic(G: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """argmin of wᵀGw − 2bᵀw within lo ≤ w ≤ hi (a bounded least-squares problem given by its normal equations)."""
    sc = np.sqrt(np.diag(G)) + 1e-300
    Gs = G / np.outer(sc, sc) + 1e-12 * np.eye(G.shape[0]) * G.shape[0]
    bs = b / sc
    try:
        L = np.linalg.cholesky(Gs)
        q = np.linalg.solve(L, bs)
        return lsq_linear(L.T, q, bounds=(lo * sc, hi * sc), method="bvls").x / sc
    except (np.linalg.LinAlgError, ValueError):  # not finite or not positive definite: the clipped solution
        with np.errstate(all="ignore"):
            w = np.linalg.lstsq(Gs, bs, rcond=None)[0] / sc if np.all(np.isfinite(Gs)) else np.zeros_like(b)
        return np.clip(np.nan_to_num(w), lo, hi)


def _lowpass(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Zero-phase low-pass of y at 10× the frequency that holds 99.5 % of the input's rate energy."""
    n = y.size
    if n < 64:
        return y
    du = np.diff(u)
    spec = np.abs(np.fft.rfft(du)) ** 2
    if spec.sum() <= 0:
        return y
    c = np.cumsum(spec) / spec.sum()
    f99 = (np.searchsorted(c, 0.995) + 1) / (n - 1)  # cycles per sample
    fc = min(10.0 * f99, 0.4)
    if fc >= 0.4:
        return y
    sos = butter(4, 2 * fc, output="sos")  # normalised to Nyquist
    return sosfiltfilt(sos, y)


def _equation_error_starts(base: MBWModel, u: np.ndarray, y: np.ndarray, a: int = 0,
                          delta2_grid: np.ndarray = DELTA2_GRID, n_offsets: int = 151, refine: int = 8,
                          max_rows: int = 4000, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Equation-error parameter sets for an MBW/BW model, one per δ2 of a grid and per regression target (the
    low-passed output, and the output itself when the low-pass changed it), ranked by free-run RMSE.

    For each δ2 and output offset c, (3.21) is linear in (δ1, ζ1, ζ2, ψ1, ψ2, α1, α2) given the (low-passed)
    measured output, so one least-squares solve gives all seven; c (which enters through |y|) is found per δ2 by
    a grid plus golden-section search on the equation-error residual.

    Parameters
    ----------
    base : MBWModel
        Supplies scaling, bounds and whether the rate terms exist.
    u, y : ndarray
        Input (V) and measured output (m) from the record start up to the end of training.
    a : int
        First scored sample (training window start).
    keep : ndarray of bool, optional
        Scored samples from ``a`` on (interleaved hold-out): held-out rows are left out of the regression and
        of the ranking.

    Returns
    -------
    thetas : ndarray, shape (m, len(base.params()))
        Candidate packed parameters, best first.
    costs : ndarray
        Their training RMSE (m) in free run; inf for diverging candidates.
    """
    un = np.ascontiguousarray(u / base.u_scale)
    kk = np.ones(un.size, dtype=bool)
    if keep is not None:
        # held-out samples must not reach the starts either: bridge them linearly before the low-pass
        kk[a:] = keep
        idx = np.arange(un.size)
        y = np.where(kk, y, np.interp(idx, idx[kk], np.asarray(y, dtype=np.float64)[kk]))
    yf = _lowpass(u, y)
    lo, hi = base.bounds
    names = base.names
    lin_names = ["delta1"] + [n for n in ("zeta1", "zeta2", "psi1", "psi2", "alpha1", "alpha2") if n in names]
    lin_idx = [names.index(n) for n in lin_names]
    k0 = max(a, 1)
    # equation rows are independent: a strided subset keeps the solve cheap on long records
    rows = np.arange(k0, un.size)
    rows = rows[kk[rows] & kk[rows - 1]]
    if rows.size > max_rows:
        rows = rows[:: int(np.ceil(rows.size / max_rows))]
    u1, u0 = un[rows], un[rows - 1]

    def regress(target: np.ndarray) -> list[np.ndarray]:
        """One candidate per δ2 of the grid from the regression on output ``target``."""
        Y1, Y0 = target[rows], target[rows - 1]
        tk = target[k0:][kk[k0:]]
        c_lo, c_hi = float(tk.min()), float(tk.max())
        pad = 0.25 * (c_hi - c_lo) + 1e-12
        # Dense, because where y dwells at a few levels (steps) the residual has many local minima in c and the
        # right one can be 4 % of the range wide (a generated magnetostrictive steps record: a 9-point grid missed
        # it and every start ended at >= 3x the noise floor); one sweep gives them all (:func:`_ee_normal_scan`).
        c_grid = np.linspace(c_lo - pad, c_hi + pad, n_offsets)
        # The offset is the reading at rest at 0 V: a record that stays far from 0 V (a piezo driven at 50-100 V)
        # has it well outside its own output range, so the search also covers the way to the straight-line
        # extrapolation of y(u) to u = 0 (on a generated record of that kind the offset lay 15 µm below every
        # reading and the starts from the output range alone ended at 27x the noise floor).
        uk = un[k0:][kk[k0:]]
        with np.errstate(all="ignore"):
            du = uk - uk.mean()
            c0 = float(tk.mean() - uk.mean() * np.dot(du, tk - tk.mean()) / np.dot(du, du))
        h = c_grid[1] - c_grid[0]
        if np.isfinite(c0) and np.isfinite(h) and h > 0 and not c_grid[0] <= c0 <= c_grid[-1]:
            # as many points again at most (a far extrapolation is coarser)
            end = c0 - pad if c0 < c_grid[0] else c0 + pad
            n_ext = int(min(np.ceil(abs(end - c_grid[0 if c0 < c_grid[0] else -1]) / h), n_offsets))
            ext = np.linspace(end, c_grid[0], n_ext + 1)[:-1] if c0 < c_grid[0] else \
                np.linspace(c_grid[-1], end, n_ext + 1)[1:]
            c_grid = np.sort(np.concatenate([c_grid, ext]))

        def solve(d2: float, c: float):
            G, b, yy = _ee_normal(Y0, Y1, u0, u1, float(c), float(d2), base.y_scale, base.rate)
            sc = np.sqrt(np.diag(G)) + 1e-300  # scale the columns to unit norm for conditioning
            G = G / np.outer(sc, sc)
            b = b / sc
            try:
                w = np.linalg.solve(G + 1e-12 * np.trace(G) * np.eye(G.shape[0]), b)
            except np.linalg.LinAlgError:
                return np.zeros(G.shape[0]), np.inf
            return w / sc, float(yy - 2.0 * np.dot(w, b) + w @ G @ w)

        def scan(d2: float) -> np.ndarray:
            """Equation-error residual at every offset of ``c_grid`` (:func:`_ee_normal_scan`, batched solves)."""
            G, b, yy = _ee_normal_scan(Y0, Y1, u0, u1, c_grid, float(d2), base.y_scale, base.rate)
            sc = np.sqrt(np.einsum("kii->ki", G)) + 1e-300
            Gs = G / (sc[:, :, None] * sc[:, None, :])
            bs = b / sc
            ridge = 1e-12 * np.einsum("kii->k", Gs)[:, None, None] * np.eye(G.shape[1])
            try:
                w = np.linalg.solve(Gs + ridge, bs[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                return np.array([solve(d2, c)[1] for c in c_grid])
            return yy - 2.0 * np.einsum("ki,ki->k", w, bs) + np.einsum("ki,kij,kj->k", w, Gs, w)

        def solve_bounded(d2: float, c: float) -> np.ndarray:
            G, b, _ = _ee_normal(Y0, Y1, u0, u1, float(c), float(d2), base.y_scale, base.rate)
            return _bounded_quadratic(G, b, lo[lin_idx], hi[lin_idx])

        g = 0.5 * (np.sqrt(5.0) - 1.0)

        def best_offset(d2: float) -> float:
            """The offset with the least equation-error residual at δ2 (dense grid, then golden section between
            the neighbours of its best point)."""
            j = int(np.argmin(scan(d2)))
            ga, gb = c_grid[max(j - 1, 0)], c_grid[min(j + 1, c_grid.size - 1)]
            x1, x2 = gb - g * (gb - ga), ga + g * (gb - ga)
            f1, f2 = solve(d2, x1)[1], solve(d2, x2)[1]
            for _ in range(refine):
                if f1 < f2:
                    gb, x2, f2 = x2, x1, f1
                    x1 = gb - g * (gb - ga)
                    f1 = solve(d2, x1)[1]
                else:
                    ga, x1, f1 = x1, x2, f2
                    x2 = ga + g * (gb - ga)
                    f2 = solve(d2, x2)[1]
            return 0.5 * (ga + gb)

        def candidate(d2: float, c: float) -> np.ndarray:
            th = base.theta0.copy()
            th[lin_idx] = solve_bounded(d2, c)
            th[names.index("delta2")] = d2
            th[names.index("offset")] = c
            return np.clip(th, lo, hi)

        return [candidate(d2, best_offset(d2)) for d2 in delta2_grid]

    # The low-passed output keeps noise out of the one-step regression, but it also removes the sample-to-sample
    # response of a stage with fast memory (δ1 ≈ 0.90, δ2 ≈ 0.93: a pole near 30 Hz at 2 kHz), and the regression
    # then lands far from it: on a generated stage of that shape its best start ended at 3.9x the noise floor,
    # while the regression on the output itself recovered the stage (2.38 nm at a 2.32 nm floor). Both are kept;
    # the free run below ranks them.
    cands = regress(yf) + (regress(np.asarray(y, dtype=np.float64)) if yf is not y else [])
    thetas = np.array(cands)
    # rank by free-run training RMSE: all candidates simulated at once
    P = np.zeros((thetas.shape[0], 8))
    for j, n in enumerate(names[:-1]):
        P[:, PARAM_NAMES.index(n)] = thetas[:, j]
    y0 = np.array([mbw_rest_state(P[i], un[0]) for i in range(P.shape[0])])  # from rest, like Model.simulate
    with np.errstate(all="ignore"):
        Y = mbw_simulate_batch(P, un, y0)
        Yhat = base.y_scale * Y[:, a:] + thetas[:, -1:]
        D = Yhat - y[a:]
        err = np.sqrt(np.mean((D if keep is None else D[:, keep]) ** 2, axis=1))
    err[~np.isfinite(err)] = np.inf
    order = np.argsort(err)
    return thetas[order], err[order]


def equation_error_starts(base: MBWModel, u: np.ndarray, y: np.ndarray, a: int = 0,
                          delta2_grid: np.ndarray = DELTA2_GRID, n_offsets: int = 151, refine: int = 8,
                          max_rows: int = 4000, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_equation_error_starts` (its docstring says all) without numpy's warnings: on a short or flat
    training window a regression divides by zero, its start is non-finite and ranked out — the warnings reached
    the user's terminal as noise (``hyst fit --train 5.9:6``)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _equation_error_starts(base, u, y, a, delta2_grid, n_offsets, refine, max_rows, keep)
