"""What every estimator shares: data checks, the split, the training cost (3.26) and the final scoring."""
from __future__ import annotations

import time
from contextlib import nullcontext
from collections.abc import Callable
from typing import Protocol, cast

import numpy as np

from ..errors import FitError
from ..model import Model
from .result import FitResult, Split, make_split, rmse

__all__ = ["Estimator", "TrainProblem", "model_label"]


def model_label(model: Model) -> str:
    """``mbw`` or ``mbw+creep+delay`` for composed models."""
    base = getattr(model, "base", None)
    effects = getattr(model, "effects", None)
    if base is not None and effects:
        return "+".join([str(base.name)] + [str(getattr(e, "name", e)) for e in effects])
    return str(model.name)


class _JacModel(Protocol):
    """A model with output sensitivities (e.g. MBW/BW): ``(yhat, dyhat/dtheta)``."""

    def simulate_jac(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


class _NormalModel(Protocol):
    """A model with fused normal equations of the normalised training residuals (MBW)."""

    def normal_equations(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray, a: int, y: np.ndarray,
                         scale: float) -> tuple[np.ndarray, np.ndarray, float]: ...


class TrainProblem:
    """The training cost of one model on one record: free-run simulation from rest up to the end of training.

    ``residuals(theta)`` returns normalised residuals (divided by ``scale``) on the training window; non-finite
    simulations (a diverging parameter set) give a large finite penalty so optimisers can step back.
    """

    #: Every normalised residual of a diverging point (finite, so optimisers can step back from it).
    PENALTY = 1e3

    def __init__(self, model: Model, t: np.ndarray, u: np.ndarray, y: np.ndarray, split: Split):
        self.t = t[:split.train_stop]
        self.u = u[:split.train_stop]
        self.y_full = y[:split.train_stop]  # for starts that look at the data before the scored window
        self.a = split.train_start
        # interleaved hold-out: masked samples are simulated (the state runs through them) but never scored;
        # the target is NaN there, which the fused MBW normal equations skip
        self.keep = None if split.val_mask is None else ~split.val_mask[split.train_start:split.train_stop]
        self.y = self.scored_target(self.y_full)
        if self.keep is not None:
            # starts (equation error, effects' data-driven starts) see held-out samples bridged linearly
            kk = np.ones(self.y_full.size, dtype=bool)
            kk[self.a:] = self.keep
            idx = np.arange(kk.size)
            self.y_full = np.where(kk, self.y_full, np.interp(idx, idx[kk], self.y_full[kk]))
        self.scale = float(np.std(self._kept(self.y))) or 1.0
        self._bind(model)

    def scored_target(self, y_full: np.ndarray) -> np.ndarray:
        """The training target from an output over the whole window (``y_full``'s shape): from the scored window's
        start, NaN where the interleaved hold-out is, as :attr:`y` holds it."""
        y = np.asarray(y_full, dtype=np.float64)[self.a:]
        return y if self.keep is None else np.where(self.keep, y, np.nan)

    def _kept(self, a: np.ndarray) -> np.ndarray:
        """The scored rows of a per-sample array (all of them without an interleaved hold-out)."""
        return a if self.keep is None else a[self.keep]

    def _bind(self, model: Model) -> None:
        """Everything that depends on the model: bounds, what it offers (Jacobian, normal equations, inactive
        parameters), a fresh evaluation count."""
        self.model = model
        self.n_eval = 0
        self._last_r: tuple[bytes, np.ndarray] | None = None
        self._last_rr: tuple[bytes, float] | None = None
        self._all: np.ndarray | None = None
        lo, hi = model.bounds
        self.lower, self.upper = lo.astype(np.float64), hi.astype(np.float64)
        self.has_jac = hasattr(model, "simulate_jac") and bool(getattr(model, "jac_available", True))
        self.has_normal = hasattr(model, "normal_equations")
        self.inactive = frozenset(getattr(model, "inactive", ()))

    def simulate_full(self, theta: np.ndarray) -> np.ndarray:
        """The model's output from the record start to the end of training (the scored window from :attr:`a`)."""
        self.n_eval += 1
        with np.errstate(all="ignore"):
            return np.asarray(self.model.simulate(np.asarray(theta, dtype=np.float64), self.t, self.u))

    def simulate(self, theta: np.ndarray) -> np.ndarray:
        return self.simulate_full(theta)[self.a:]

    def _keep_all(self) -> np.ndarray:
        """:attr:`keep`, or every scored row."""
        if self.keep is not None:
            return self.keep
        if self._all is None or self._all.size != self.y.size:
            self._all = np.ones(self.y.size, dtype=np.bool_)
        return self._all

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=np.float64)
        key = theta.tobytes()
        if self._last_r is not None and self._last_r[0] == key:  # a cost just taken at the point LM accepts
            return self._last_r[1]
        with np.errstate(all="ignore"):  # a diverging trial point is penalised below, not warned about
            r = self._kept((self.simulate(theta) - self.y) / self.scale)
        if not np.all(np.isfinite(r)):
            r = np.full(r.size, self.PENALTY)
        self._last_r = (key, r)
        return r

    def sum_squares(self, theta: np.ndarray) -> float:
        """rᵀr of the normalised residuals (a trial point's cost in :func:`~hyst_model.identify.lm.bounded_lm`).

        Where the normal equations do not come from the residuals (sensitivities), the residuals are not kept:
        their squares are summed in the simulation's own pass (:func:`~hyst_model.identify.lm.scored_sum_squares`,
        bit for bit the sum of :meth:`residuals`, the last point remembered as there)."""
        from .lm import scored_sum_squares, sum_squares
        if not (self.has_jac or self.has_normal):  # forward differences reuse the residuals kept here
            return float(sum_squares(np.ascontiguousarray(self.residuals(theta))))
        theta = np.asarray(theta, dtype=np.float64)
        key = theta.tobytes()
        if self._last_rr is not None and self._last_rr[0] == key:
            return self._last_rr[1]
        rr = float(scored_sum_squares(np.ascontiguousarray(self.simulate_full(theta), dtype=np.float64), self.a,
                                      np.ascontiguousarray(self.y), self.scale, self._keep_all(), self.PENALTY))
        self._last_rr = (key, rr)
        return rr

    def for_model(self, model: Model) -> "TrainProblem":
        """The same record and windows for another model (e.g. the base of a composed model)."""
        p = TrainProblem.__new__(TrainProblem)
        p.__dict__.update(self.__dict__)
        p._bind(model)
        return p

    def jac(self, theta: np.ndarray) -> np.ndarray:
        """Jacobian of the normalised residuals (models with simulate_jac: used only when :attr:`has_jac`)."""
        model = cast(_JacModel, self.model)
        self.n_eval += 1
        with np.errstate(all="ignore"):
            _, J = model.simulate_jac(np.asarray(theta, dtype=np.float64), self.t, self.u)
        J = self._kept(J[self.a:]) / self.scale
        if not np.all(np.isfinite(J)):
            J = np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)
        return J

    def residuals_jac(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised residuals and their Jacobian from one sensitivity simulation (models with simulate_jac)."""
        model = cast(_JacModel, self.model)  # used only when has_jac
        self.n_eval += 1
        with np.errstate(all="ignore"):
            yhat, J = model.simulate_jac(np.asarray(theta, dtype=np.float64), self.t, self.u)
        r = self._kept((yhat[self.a:] - self.y) / self.scale)
        J = self._kept(J[self.a:])
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
            return np.full(r.size, np.inf), np.zeros((r.size, theta.size))
        return r, J / self.scale

    def fd_residuals_jac(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals and a forward-difference Jacobian (p + 1 simulations), stepping inward at bounds.

        Parameters the model declares ``inactive`` (the output does not depend on them) get a zero column
        without a simulation. Columns go last parameter first: a composed model's outer effects come last, and
        its inner stages, unchanged by their steps, are reused (``reusing_stages``) before the base parameters'
        steps replace them.
        """
        reuse = getattr(self.model, "reusing_stages", None)
        with reuse() if reuse is not None else nullcontext():
            return self._fd_residuals_jac(np.asarray(theta, dtype=np.float64))

    def _fd_residuals_jac(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r0 = self.residuals(theta)
        J = np.zeros((r0.size, theta.size))
        span = self.upper - self.lower
        for i in reversed(range(theta.size)):
            if i in self.inactive:
                continue
            h = 1e-6 * max(abs(theta[i]), 1e-3 * span[i] if np.isfinite(span[i]) else 1e-3, 1e-12)
            if theta[i] + h > self.upper[i]:
                h = -h
            tp = theta.copy()
            tp[i] += h
            J[:, i] = (self.residuals(tp) - r0) / h
        return r0, J

    def normal_equations(self, theta: np.ndarray):
        """``(JᵀJ, Jᵀr, rᵀr)`` of the normalised residuals: fused (MBW), from one sensitivity simulation summed in
        one compiled pass (what :meth:`residuals_jac` gives, bit for bit) or from forward differences."""
        if self.has_normal:
            model = cast(_NormalModel, self.model)  # has_normal: hasattr(model, "normal_equations")
            self.n_eval += 1
            with np.errstate(all="ignore"):
                return model.normal_equations(np.asarray(theta, dtype=np.float64), self.t, self.u, self.a,
                                                   self.y, self.scale)
        theta = np.asarray(theta, dtype=np.float64)
        if self.has_jac:  # residuals_jac and normal_from_jac fused into one compiled pass (the same sums)
            from .lm import scored_normal_equations
            jm = cast(_JacModel, self.model)
            self.n_eval += 1
            with np.errstate(all="ignore"):
                yhat, J = jm.simulate_jac(theta, self.t, self.u)
            return scored_normal_equations(np.ascontiguousarray(yhat, dtype=np.float64),
                                           np.ascontiguousarray(J, dtype=np.float64), self.a,
                                           np.ascontiguousarray(self.y), self.scale, self._keep_all())
        from .lm import normal_from_jac
        return normal_from_jac(self.fd_residuals_jac)(theta)

    def cost(self, theta: np.ndarray) -> float:
        """Training RMSE (m), inf for a diverging parameter set."""
        r = self._kept(self.simulate(theta) - self.y)
        return rmse(r) if np.all(np.isfinite(r)) else float("inf")

    def clip(self, theta: np.ndarray, margin: float = 1e-9) -> np.ndarray:
        """Strictly inside the bounds (trust-region solvers need an interior start)."""
        span = self.upper - self.lower
        return np.clip(theta, self.lower + margin * span, self.upper - margin * span)


class Estimator:
    """Base class: ``fit(t, u, y)`` returns self with ``theta_``, ``params_``, ``result_``.

    Parameters
    ----------
    model : Model
        Any model implementing :class:`hyst_model.model.Model` (composed models included).
    split : float or (t0, t1) or None
        Train/validation split, see :mod:`hyst_model.identify.result`.
    progress : callable or bool, optional
        ``progress(message: str)`` receives status lines; True prints them to stderr.
    """

    method = "base"

    def __init__(self, model: Model, *, split=0.25, progress: Callable[[str], None] | bool | None = None):
        self.model = model
        self.split = split
        self.progress: Callable[[str], None] | None
        if progress is True:
            import sys
            self.progress = lambda msg: print(msg, file=sys.stderr, flush=True)
        else:
            self.progress = progress or None

    def _say(self, msg: str) -> None:
        if self.progress:
            self.progress(msg)

    def _solve(self, problem: TrainProblem) -> tuple[np.ndarray, int, list, str]:
        """Return ``(theta, n_iterations, history, message)``; implemented by subclasses."""
        raise NotImplementedError

    def fit(self, t, u, y) -> "Estimator":
        t = np.ascontiguousarray(t, dtype=np.float64)
        u = np.ascontiguousarray(u, dtype=np.float64)
        y = np.ascontiguousarray(y, dtype=np.float64)
        if not (t.size == u.size == y.size):
            raise FitError("t, u, y must have the same length")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y)) and np.all(np.isfinite(t))):
            raise FitError("data contain NaN/inf; check the record first")
        split = make_split(t, self.split)
        if np.ptp(u[:split.train_stop]) == 0:
            raise FitError("the input does not vary up to the end of the training window: nothing to identify")
        if np.ptp(y[split.train_index()]) == 0:  # a dead or unplugged sensor: a fit made a model of nothing
            raise FitError("the output does not vary on the training samples: nothing to identify (is the sensor "
                           "connected?)")
        t0 = time.perf_counter()
        problem = TrainProblem(self.model, t, u, y, split)
        theta, n_iter, history, message = self._solve(problem)
        seconds = time.perf_counter() - t0
        with np.errstate(all="ignore"):
            yhat = np.asarray(self.model.simulate(theta, t, u))
        res = y - yhat
        r_tr = rmse(res[split.train_index()])
        r_val = rmse(res[split.val_index()]) if split.has_validation else r_tr
        if not np.isfinite(r_tr):
            raise FitError(f"{self.method} fit diverged (no finite parameter set found)")
        self.theta_ = np.asarray(theta, dtype=np.float64)
        self.params_ = self.model.unpack(self.theta_)
        self.split_ = split
        self.result_ = FitResult(model=model_label(self.model), method=self.method, params=dict(self.params_),
                                 theta=self.theta_, rmse_train=r_tr, rmse=r_val, seconds=seconds,
                                 n_evaluations=problem.n_eval, n_iterations=int(n_iter), residuals=res,
                                 split=split.description, cost=r_tr, history=list(history), message=message,
                                 validated=split.has_validation)
        return self
