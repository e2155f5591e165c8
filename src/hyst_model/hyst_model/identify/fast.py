"""The default identifier: an equation-error start, then output-error bounded least squares from a few starts.

Why it is fast
--------------
Given the measured output, MBW (3.21) is *linear* in (ζ1, ζ2, ψ1, ψ2, α1, α2) for fixed δ1, δ2 and offset c:

.. math::  y_k - \\delta_1 y_{k-1} = [\\nu_k,\\ v_k\\nu_k,\\ -|\\nu_k| y_{k-1},\\ -v_k|\\nu_k| y_{k-1},\\
           -\\nu_k|y_{k-1}|,\\ -v_k\\nu_k|y_{k-1}|]\\,(\\zeta_1, \\zeta_2, \\psi_1, \\psi_2, \\alpha_1, \\alpha_2)^T

and δ1 enters linearly as well, so a grid over δ2 and a few offset guesses costs one small least-squares solve each (equation error, on a
zero-phase low-passed y because differencing amplifies sensor noise). Every grid candidate is then simulated in
free run at once (:func:`hyst_model.core.mbw.mbw_simulate_batch`) and the best few distinct ones start an
output-error fit of the free-run residual within the parameter bounds: for models with an exact Jacobian
(``simulate_jac``: MBW/BW forward sensitivities) a compact bounded Levenberg-Marquardt on the p × p normal equations
(:mod:`.lm`), otherwise :func:`scipy.optimize.least_squares` (trust-region reflective, finite differences).
δ1, δ2 and the offset are fitted too.

Any model works: a composed model (``.base`` + effects) gets the equation-error start on its base (when the base
is MBW/BW) and its declared defaults for the effect parameters; other models start from their defaults.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, sosfiltfilt

from ..core.mbw import PARAM_NAMES, mbw_simulate_batch
from ..model import MBWModel, Model
from .base import Estimator, TrainProblem
from .lm import _normal_equations, bounded_lm

__all__ = ["FastFit", "equation_error_starts", "DELTA2_GRID"]

#: δ2 grid for the equation-error stage (δ ≈ 1 − Δt/τ; see the thesis README on relaxation). δ1 is regressed.
DELTA2_GRID = 1.0 - np.array([0.0, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 0.01, 0.02, 0.03, 0.04, 0.05, 0.07, 0.1,
                              0.15, 0.2, 0.3, 0.5])


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


def equation_error_starts(base: MBWModel, u: np.ndarray, y: np.ndarray, a: int = 0,
                          delta2_grid: np.ndarray = DELTA2_GRID, n_offsets: int = 9, refine: int = 18,
                          max_rows: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """Equation-error parameter sets for an MBW/BW model, one per δ2 of a grid, ranked by free-run RMSE.

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

    Returns
    -------
    thetas : ndarray, shape (m, len(base.params()))
        Candidate packed parameters, best first.
    costs : ndarray
        Their training RMSE (m) in free run; inf for diverging candidates.
    """
    un = np.ascontiguousarray(u / base.u_scale)
    yf = _lowpass(u, y)
    lo, hi = base.bounds
    names = base.names
    lin_names = ["delta1"] + [n for n in ("zeta1", "zeta2", "psi1", "psi2", "alpha1", "alpha2") if n in names]
    lin_idx = [names.index(n) for n in lin_names]
    k0 = max(a, 1)
    # equation rows are independent: a strided subset keeps the solve cheap on long records
    rows = np.arange(k0, un.size)
    if rows.size > max_rows:
        rows = rows[:: int(np.ceil(rows.size / max_rows))]
    u1, u0 = un[rows], un[rows - 1]
    v = np.abs(u1 - u0)
    Y1, Y0 = yf[rows], yf[rows - 1]
    c_lo, c_hi = float(yf[k0:].min()), float(yf[k0:].max())
    pad = 0.25 * (c_hi - c_lo) + 1e-12

    def solve(d2: float, c: float):
        yp = (Y0 - c) / base.y_scale
        yk = (Y1 - c) / base.y_scale
        nu = u1 - d2 * u0
        cols = [yp, nu, v * nu, -np.abs(nu) * yp, -v * np.abs(nu) * yp, -nu * np.abs(yp), -v * nu * np.abs(yp)]
        if not base.rate:
            cols = [cols[0], cols[1], cols[3], cols[5]]
        X = np.column_stack(cols)
        G, b, yy = _normal_equations(X, yk)  # a 7x7 solve per candidate instead of an SVD
        sc = np.sqrt(np.diag(G)) + 1e-300  # scale the columns to unit norm for conditioning
        G = G / np.outer(sc, sc)
        b = b / sc
        try:
            w = np.linalg.solve(G + 1e-12 * np.trace(G) * np.eye(G.shape[0]), b)
        except np.linalg.LinAlgError:
            return np.zeros(G.shape[0]), np.inf
        return w / sc, float(yy - 2.0 * np.dot(w, b) + w @ G @ w)

    cands = []
    c_grid = np.linspace(c_lo - pad, c_hi + pad, n_offsets)
    for d2 in delta2_grid:
        errs = [solve(d2, c)[1] for c in c_grid]
        j = int(np.argmin(errs))
        # golden-section refinement of the offset between the neighbours of the best grid point
        ga, gb = c_grid[max(j - 1, 0)], c_grid[min(j + 1, c_grid.size - 1)]
        g = 0.5 * (np.sqrt(5.0) - 1.0)
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
        c = 0.5 * (ga + gb)
        w, _ = solve(d2, c)
        th = base.theta0.copy()
        th[lin_idx] = w
        th[names.index("delta2")] = d2
        th[names.index("offset")] = c
        cands.append(np.clip(th, lo, hi))
    thetas = np.array(cands)
    # rank by free-run training RMSE: all candidates simulated at once
    P = np.zeros((thetas.shape[0], 8))
    for j, n in enumerate(names[:-1]):
        P[:, PARAM_NAMES.index(n)] = thetas[:, j]
    with np.errstate(all="ignore"):
        Y = mbw_simulate_batch(P, un, np.zeros(P.shape[0]))
        Yhat = base.y_scale * Y[:, a:] + thetas[:, -1:]
        err = np.sqrt(np.mean((Yhat - y[a:]) ** 2, axis=1))
    err[~np.isfinite(err)] = np.inf
    order = np.argsort(err)
    return thetas[order], err[order]


class FastFit(Estimator):
    """Equation-error start + multi-start output-error least squares (the default ``method='fast'``).

    Parameters
    ----------
    model : Model
        Any model; MBW/BW bases get the equation-error start.
    n_starts : int
        Output-error runs from the best distinct starts.
    max_nfev : int
        Iteration budget of the final output-error run (each start gets a third of it first).
    split, progress
        See :class:`~hyst_model.identify.base.Estimator`.
    """

    method = "fast"

    def __init__(self, model: Model, *, n_starts: int = 3, max_nfev: int = 120, split=0.25, progress=None):
        super().__init__(model, split=split, progress=progress)
        self.n_starts = int(n_starts)
        self.max_nfev = int(max_nfev)

    def _starts(self, problem: TrainProblem) -> list[np.ndarray]:
        model = self.model
        base = getattr(model, "base", model)
        theta0 = problem.clip(model.theta0)
        if not isinstance(base, MBWModel):
            return [theta0]
        thetas, costs = equation_error_starts(base, problem.u, problem.y_full, problem.a)
        problem.n_eval += len(thetas)
        self._say(f"fast: equation-error grid {len(thetas)} candidates, best free-run RMSE {costs[0]:.4g} m")
        starts: list[np.ndarray] = []
        dnames = [base.names.index("delta1"), base.names.index("delta2")]
        for th, c in zip(thetas, costs):
            if not np.isfinite(c):
                break
            if any(np.all(np.abs(th[dnames] - s[dnames]) < 1e-12) for s in starts):
                continue  # distinct (δ1, δ2) pairs only
            starts.append(th)
            if len(starts) >= self.n_starts:
                break
        out = []
        for th in starts or [base.theta0]:
            out.append(problem.clip(model.pack(base.unpack(th))))
        if not starts:
            out.append(theta0)
        return out

    def _run(self, problem: TrainProblem, x0: np.ndarray, nfev: int):
        if problem.has_jac:  # exact sensitivities: the compact normal-equation LM is ~10x cheaper per iteration
            return bounded_lm(problem.residuals_jac, x0, problem.lower, problem.upper, max_iter=nfev)
        return least_squares(problem.residuals, x0, jac=jac, bounds=(problem.lower, problem.upper),
                             method="trf", x_scale="jac", max_nfev=nfev, ftol=1e-10, xtol=1e-10, gtol=1e-10,
                             tr_solver="lsmr")  # iterative trust-region solve: no n x p SVD per iteration

    def _solve(self, problem: TrainProblem):
        starts = self._starts(problem)
        best, history, iters = None, [], 0
        per = max(self.max_nfev // 3, 10)
        for i, x0 in enumerate(starts):
            sol = self._run(problem, x0, per if len(starts) > 1 else self.max_nfev)
            iters += int(sol.nfev)
            c = problem.cost(sol.x)
            history.append(c)
            self._say(f"fast: start {i + 1}/{len(starts)} -> training RMSE {c:.4g} m ({sol.nfev} iterations)")
            if best is None or c < best[1]:
                best = (sol, c)
        sol = best[0]
        msg = sol.message
        if len(starts) > 1 and sol.status == 0:  # budget ran out: continue the winner
            sol = self._run(problem, problem.clip(sol.x), self.max_nfev)
            iters += int(sol.nfev)
            msg = sol.message
            history.append(problem.cost(sol.x))
            self._say(f"fast: refined -> training RMSE {history[-1]:.4g} m")
        return sol.x, iters, history, str(msg)
