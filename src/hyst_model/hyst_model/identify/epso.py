"""The thesis's extended particle swarm optimisation (EPSO), ch. 3.4.3, eqs. (3.22)–(3.27).

* chaotic acceleration (3.22): ϑ_{k+1} = η ϑ_k (1 − ϑ_k), η = 4, ϑ_0 drawn at random (avoiding the map's fixed
  and periodic points 0, ¼, ½, ¾, 1);
* velocity and position (3.23)–(3.24): v ← I_w v + ρ1 r1 (Pb − x) + ϑ_k ρ2 r2 (Gb − x), x ← x + ϑ_k v, with
  ρ1 = 1.5, ρ2 = 2.5 and r1, r2 ~ U(0, 1) per particle and dimension;
* inertia (3.25): I_w = I_max − (I_max − I_min) e^{−0.02 ϑ_k} k / N, I_max = 0.9, I_min = 0.2, N = iterations;
* 40 particles; the thesis's Table 3.1 bounds for (ζ1, ζ2, ψ1, ψ2, α1, α2); cost = RMSE (3.26)–(3.27).

Choices the thesis leaves open, stated here: particles start uniformly in the bounds with zero velocity;
positions are clipped to the bounds and velocities to ±(upper − lower); δ1, δ2 and the output offset (which
(3.27) does not list because the thesis fixes them) are searched too, within the model's bounds, because real data
needs them. MBW/BW swarms are evaluated all at once with :func:`hyst_model.core.mbw.mbw_simulate_batch`; other
models one particle at a time.

The thesis contradicts itself here: Table 3.1 keeps α1 ≥ −1e-5 and ψ1 ≥ 1e-5, so no fit inside its bounds meets
Remark 4.1 (α1 < −|ψ1|), which the control laws assume. ``hyst fit`` checks every fit against Remark 4.1 and says
so; ``--admissible`` fits inside it.
"""
from __future__ import annotations

import sys

import numpy as np

from ..core.mbw import PARAM_NAMES, mbw_simulate_batch
from ..core.params import TABLE31_BOUNDS
from ..model import MBWModel, Model
from .base import Estimator, TrainProblem

__all__ = ["EPSOFit", "ETA", "RHO1", "RHO2", "I_MAX", "I_MIN", "PARTICLES", "chaotic_sequence", "inertia"]

ETA, RHO1, RHO2, I_MAX, I_MIN, PARTICLES = 4.0, 1.5, 2.5, 0.9, 0.2, 40
_AVOID = (0.0, 0.25, 0.5, 0.75, 1.0)


def chaotic_sequence(theta0: float, n: int, eta: float = ETA) -> np.ndarray:
    """ϑ_0..ϑ_{n−1} of the logistic map (3.22)."""
    out = np.empty(n)
    th = theta0
    for k in range(n):
        out[k] = th
        th = eta * th * (1.0 - th)
    return out


def inertia(k: int, n: int, theta_k: float) -> float:
    """Dynamic inertia weight (3.25)."""
    return I_MAX - (I_MAX - I_MIN) * np.exp(-0.02 * theta_k) * k / n


class EPSOFit(Estimator):
    """Extended PSO (3.22)–(3.27).

    Parameters
    ----------
    model : Model
        Model to fit; MBW/BW get Table 3.1 bounds on the shape parameters (``bounds='table3.1'``).
    iterations : int
        Swarm generations N of (3.25).
    particles : int
        Swarm size N_s (thesis: 40).
    seed : int, optional
        Seeds r1, r2, the initial swarm and ϑ_0.
    bounds : {'table3.1', 'model'}
        Search box for the shape parameters.
    progress : callable or bool
        ``True`` draws a one-line progress display on stderr.
    """

    method = "epso"

    def __init__(self, model: Model, *, iterations: int = 200, particles: int = PARTICLES, seed: int | None = None,
                 bounds: str = "table3.1", split=0.25, progress=None):
        live = progress is True
        super().__init__(model, split=split, progress=progress)
        if iterations < 1 or particles < 2:
            raise ValueError("EPSO needs iterations >= 1 and particles >= 2")
        if bounds not in ("table3.1", "model"):
            raise ValueError("bounds must be 'table3.1' or 'model'")
        self.iterations = int(iterations)
        self.particles = int(particles)
        self.seed = seed
        self.bounds = bounds
        self._live = live and sys.stderr.isatty()

    def _box(self, problem: TrainProblem) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = problem.lower.copy(), problem.upper.copy()
        if self.bounds == "table3.1":
            for i, n in enumerate(self.model.names):
                if n in TABLE31_BOUNDS:
                    lo[i], hi[i] = TABLE31_BOUNDS[n]
        return lo, hi

    def _batch_cost(self, problem: TrainProblem, X: np.ndarray) -> np.ndarray:
        model = self.model
        if isinstance(model, MBWModel):
            P = np.zeros((X.shape[0], 8))
            for j, n in enumerate(model.names[:-1]):
                P[:, PARAM_NAMES.index(n)] = X[:, j]
            un = np.ascontiguousarray(problem.u / model.u_scale)
            # from rest at u[0]: the recursions start where holding u[0] leaves them (zero for u[0] = 0)
            from ..core.mbw import mbw_rest_state
            y0 = np.array([mbw_rest_state(P[i], un[0]) for i in range(P.shape[0])]) if un[0] != 0 else \
                np.zeros(P.shape[0])
            with np.errstate(all="ignore"):
                Y = mbw_simulate_batch(P, un, y0)[:, problem.a:] * model.y_scale + X[:, -1:]
                D = Y - problem.y
                c = np.sqrt(np.mean((D if problem.keep is None else D[:, problem.keep]) ** 2, axis=1))
            problem.n_eval += X.shape[0]
        else:
            c = np.array([problem.cost(x) for x in X])
        c[~np.isfinite(c)] = np.inf
        return c

    def _solve(self, problem: TrainProblem):
        rng = np.random.default_rng(self.seed)
        lo, hi = self._box(problem)
        span = hi - lo
        ns, d, n_it = self.particles, lo.size, self.iterations
        th0 = rng.uniform(0.01, 0.99)
        while any(abs(th0 - a) < 1e-6 for a in _AVOID):
            th0 = rng.uniform(0.01, 0.99)
        chaos = chaotic_sequence(th0, n_it)
        X = lo + rng.uniform(size=(ns, d)) * span
        V = np.zeros((ns, d))
        cost = self._batch_cost(problem, X)
        pbest, pcost = X.copy(), cost.copy()
        g = int(np.argmin(pcost))
        gbest, gcost = pbest[g].copy(), float(pcost[g])
        history = []
        for k in range(n_it):
            th = chaos[k]
            iw = inertia(k, n_it, th)
            r1 = rng.uniform(size=(ns, d))
            r2 = rng.uniform(size=(ns, d))
            V = iw * V + RHO1 * r1 * (pbest - X) + th * RHO2 * r2 * (gbest - X)  # (3.23)
            V = np.clip(V, -span, span)
            X = np.clip(X + th * V, lo, hi)  # (3.24)
            cost = self._batch_cost(problem, X)
            better = cost < pcost
            pbest[better], pcost[better] = X[better], cost[better]
            g = int(np.argmin(pcost))
            if pcost[g] < gcost:
                gbest, gcost = pbest[g].copy(), float(pcost[g])
            history.append(gcost)
            self._report(k + 1, n_it, gcost)
        if self._live:
            print(file=sys.stderr)
        return gbest, n_it, history, f"EPSO: {n_it} iterations x {ns} particles"

    def _report(self, k: int, n: int, best: float) -> None:
        if not self.progress:
            return
        if self._live:
            bar = int(30 * k / n)
            print(f"\repso [{'#' * bar}{'.' * (30 - bar)}] {k}/{n}  best RMSE {best:.4g} m", end="",
                  file=sys.stderr, flush=True)
        elif k == n or k % max(n // 10, 1) == 0:
            self._say(f"epso: iteration {k}/{n}, best RMSE {best:.4g} m")
