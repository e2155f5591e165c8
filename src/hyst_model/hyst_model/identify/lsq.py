"""LSQM baseline: bounded nonlinear least squares of the free-run output error from a fixed start.

This is the classical approach the thesis compares EPSO against (§3.4.3, model validation: "the common
identification technique is not effective"): trust-region-reflective least squares
(:func:`scipy.optimize.least_squares`) started from the model's declared defaults, one start, no equation-error
initialisation. It shows what :mod:`.fast` gains from its starts.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..model import Model
from .base import Estimator, TrainProblem

__all__ = ["LSQFit"]


class LSQFit(Estimator):
    """Bounded least squares from ``theta0`` (default: the model's parameter defaults).

    Parameters
    ----------
    model : Model
        Model to fit.
    theta0 : array_like, optional
        Fixed start.
    max_nfev : int
        Iteration budget.
    """

    method = "lsq"

    def __init__(self, model: Model, *, theta0=None, max_nfev: int = 200, split=0.25, progress=None):
        super().__init__(model, split=split, progress=progress)
        self.theta0 = None if theta0 is None else np.asarray(theta0, dtype=np.float64)
        self.max_nfev = int(max_nfev)

    def _solve(self, problem: TrainProblem):
        x0 = problem.clip(self.model.theta0 if self.theta0 is None else self.theta0)
        jac = problem.jac if problem.has_jac else "2-point"
        if not problem.has_jac and problem.inactive:  # skip the columns the output does not depend on
            def jac(th):
                return problem.fd_residuals_jac(th)[1]
        sol = least_squares(problem.residuals, x0, jac=jac, bounds=(problem.lower, problem.upper), method="trf",
                            x_scale="jac", max_nfev=self.max_nfev)
        c = problem.cost(sol.x)
        self._say(f"lsq: training RMSE {c:.4g} m after {sol.nfev} iterations ({sol.message})")
        return sol.x, int(sol.nfev), [c], str(sol.message)
