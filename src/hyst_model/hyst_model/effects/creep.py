"""Creep: the slow, logarithmic-in-time extra displacement of a piezo stack after a change.

After a voltage step a piezo keeps extending for seconds to minutes, roughly linearly in log(time)
(Jung & Gweon, Rev. Sci. Instrum. 71, 2000; Kuhnen's creep operator). The MBW's δ terms relax with one time
constant only (../shared/thesis/README.md, "The δ terms already relax"), so a base model leaves a residual that
keeps growing after each step. The creep operator here acts on the hysteretic displacement x = y_inner with
first-order lags c_i of log-spaced time constants τ_i (0.01 s … 300 s, ``PER_DECADE`` per decade):

    y = x − gain · (n / PER_DECADE) · Σ_i w_i (x − c_i),   τ_i ċ_i = x − c_i,   w_i ∝ (τ_i / 1 s)^tilt, Σ w_i = 1

At rest every c_i equals x, so a long-held input reads exactly the base model's static map (quasi-static data
fix the hysteresis, creep adds only the slow approach to it). After a step Δ the output falls short by
``gain · Δ`` per remaining decade of τ and recovers linearly in log time (tilt = 0): ``gain`` is the creep per
decade of time as a fraction of the step. Lags start at rest at x[0] and are discretised exactly for a held
input, with the record's own sample time (so decimated screening copies work unchanged).

``creep.form: lags`` is the other common description of creep: a few Kelvin-Voigt elements, here two first-order
lags with free time constants (Jung & Gweon's and Kuhnen's creep operators are sums of such lags with fixed
constants; a stage whose creep settles within seconds has its spectrum in one or two of them, which the log law's
power-law weights over 0.01-300 s cannot concentrate — they leave a slow ramp that reads as drift):

    y = x − gain · (share · (x − c_1) + (1 − share) · (x − c_2)),   τ_j ċ_j = x − c_j,   0.01 s ≤ τ_j ≤ tau_max

with ``creep.tau_max`` a third of the span the fit scores (:meth:`Creep.data_config`; 300 s at most).

``gain`` is then the share of a step that creeps in all (the output follows a step Δ at once by (1 − gain)·Δ and
reaches Δ as the lags settle). ``hyst diagnose`` tries both forms and keeps the one that validates better.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import EffectError
from ..model import Param
from .base import Effect
from .online import OnlineEffect
from .signals import holds, sample_time

__all__ = ["Creep", "CreepInverse", "creep_lags", "TAUS", "PER_DECADE", "FORMS"]

PER_DECADE = 3
#: Time constants of the creep operator (s): 0.01 s … 300 s.
TAUS = np.logspace(-2, np.log10(300.0), int(round(PER_DECADE * np.log10(300.0 / 0.01))) + 1)
#: The operator's forms: power-law weights over :data:`TAUS` (the log law), or two lags with free time constants.
FORMS = ("log", "lags")
#: Least share of the creep either lag of the lags form starts with (:func:`_lags_start`).
MIN_START_SHARE = 0.2


@njit(cache=True, nogil=True)
def _lag_bank(x: np.ndarray, a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Σ_i w_i c_i for lags c_i ← a_i c_i + (1 − a_i) x_k, all at rest at x[0] (one pass, compiled)."""
    n = x.shape[0]
    m = a.shape[0]
    c = np.full(m, x[0])
    out = np.empty(n)
    for k in range(n):
        s = 0.0
        xk = x[k]
        for i in range(m):
            c[i] = a[i] * c[i] + (1.0 - a[i]) * xk
            s += w[i] * c[i]
        out[k] = s
    return out


@njit(cache=True, nogil=True)
def _creep_cols(X: np.ndarray, a: np.ndarray, w: np.ndarray, g: float) -> np.ndarray:
    """X − g (X − L) for :func:`_lag_bank` L of every column of ``X`` (n, k), in one pass (the columns vectorise;
    the operator applied in the bank's own loop, so no n × k temporaries: the same arithmetic element by
    element as the array expression)."""
    n, k = X.shape
    m = a.shape[0]
    c = np.empty((m, k))
    for i in range(m):
        c[i, :] = X[0, :]
    out = np.empty((n, k))
    s = np.empty(k)
    for r in range(n):
        s[:] = 0.0
        for i in range(m):
            ai = a[i]
            bi = 1.0 - ai
            wi = w[i]
            for j in range(k):
                c[i, j] = ai * c[i, j] + bi * X[r, j]
                s[j] += wi * c[i, j]
        for j in range(k):
            out[r, j] = X[r, j] - g * (X[r, j] - s[j])
    return out


def creep_lags(t: np.ndarray, x: np.ndarray, taus: np.ndarray = TAUS) -> np.ndarray:
    """States c_i (shape (len(taus), n)) of first-order lags driven by ``x``, at rest at ``x[0]``."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    a = np.exp(-sample_time(t) / taus)
    return np.vstack([_lag_bank(x, a[i:i + 1], np.ones(1)) for i in range(taus.size)])


def _weights(tilt: float, taus: np.ndarray = TAUS) -> np.ndarray:
    w = np.exp(tilt * np.log(taus))
    return w / w.sum()


def creep_term(t: np.ndarray, x: np.ndarray, tilt: float = 0.0) -> np.ndarray:
    """(n / PER_DECADE) · Σ w_i (x − c_i): the creep deficit per unit gain."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    a = np.exp(-sample_time(t) / TAUS)
    return (TAUS.size / PER_DECADE) * (x - _lag_bank(x, a, _weights(tilt)))


class Creep(Effect):
    """Creep operator on the hysteretic displacement: first-order lags, zero static contribution (two forms)."""

    name = "creep"
    summary = "slow extra displacement after changes, growing linearly in log time (piezo creep)"
    physics = ("After a step the stage keeps moving for seconds to minutes, about the same amount per decade of "
               "time; modelled as first-order lags with time constants 0.01-300 s acting on the displacement.")
    kind = "output"
    linear = True  # x − g·N·Σ w_i (x − lag_i(x)): lags at rest

    def __init__(self, config=None):
        super().__init__(config)
        self.form = str(self._config.get("creep.form", "log"))
        if self.form not in FORMS:
            raise EffectError(f"creep.form must be one of {', '.join(FORMS)}, not {self.form!r}")
        self.tau_max = float(self._config.get("creep.tau_max", TAUS[-1]))
        if not TAUS[0] < self.tau_max <= TAUS[-1]:
            raise EffectError(f"creep.tau_max must lie in ({TAUS[0]:g}, {TAUS[-1]:g}] s, not {self.tau_max:g}")

    @classmethod
    def data_config(cls, t, u, y, scored):
        """The lags form's longest time constant: a third of the span the fit scores (a lag settles 95 % within
        it). A slower lag shows on the record only as the ramp its response starts with — the record cannot tell
        it from drift (the hidden drift bag: a lag of 193 s took the whole drift, and creep was named)."""
        tt = np.asarray(t, dtype=np.float64)[np.asarray(scored, bool)]
        if tt.size < 2:
            return {}
        return {"creep.tau_max": float(np.clip((tt[-1] - tt[0]) / 3.0, 2.0 * TAUS[0], TAUS[-1]))}

    @staticmethod
    def variants() -> list[dict[str, str]]:
        """Configurations ``hyst diagnose`` tries, keeping whichever validates better: both forms."""
        return [{"creep.form": f} for f in FORMS]

    def screen_with_refit(self) -> bool:
        # The base's δ terms relax like a fast lag and take up part of the creep when fitted without it, so with
        # the base held fixed the forms are misjudged: on the hidden creep + delay bag, on top of the delay, the
        # lags screened better (59.4 against 63.3 nm) while refitted jointly the log law reached the noise
        # (2.1 nm) and the lags 12.2 nm. The forms are compared refitted, as asymmetry's are.
        return True

    def params(self):
        if self.form == "lags":
            return (Param("gain", 0.0, -0.3, 0.6, "", "share of a step that creeps, in all"),
                    Param("tau1", min(0.1, self.tau_max), TAUS[0], self.tau_max, "s",
                          "time constant of the first lag"),
                    Param("tau2", min(3.0, self.tau_max), TAUS[0], self.tau_max, "s",
                          "time constant of the second lag"),
                    Param("share", 0.5, 0.0, 1.0, "", "the first lag's share of the creep"))
        return (Param("gain", 0.0, -0.1, 0.3, "1/decade", "creep per decade of time, fraction of a step"),
                Param("tilt", 0.0, -0.3, 0.3, "", "weight of slow vs fast lags: w_i ∝ τ_i^tilt"))

    def config(self):
        # the form always: a node declares every effect key with its plain default, "log"
        return {"form": self.form, "tau_max": self.tau_max} if self.form == "lags" else {"form": self.form}

    def bank(self, theta) -> tuple[float, np.ndarray, np.ndarray]:
        """``(g, taus, w)``: the operator is y = x − g · Σ w_i (x − c_i) with lags of time constants ``taus``."""
        if self.form == "lags":
            share = float(theta[3])
            return float(theta[0]), np.array([float(theta[1]), float(theta[2])]), np.array([share, 1.0 - share])
        return float(theta[0]) * TAUS.size / PER_DECADE, TAUS, _weights(float(theta[1]))

    def output(self, theta, t, u, y):
        if self.form == "log":  # its own expression: the log form's outputs stay bit for bit what they were
            gain, tilt = float(theta[0]), float(theta[1])
            return y if gain == 0.0 else y - gain * creep_term(t, y, tilt)
        g, taus, w = self.bank(theta)
        if g == 0.0:
            return y
        x = np.ascontiguousarray(y, dtype=np.float64)
        return x - g * (x - _lag_bank(x, np.exp(-sample_time(t) / taus), w))

    def push(self, theta, t, u, x, y, J):
        """Columns ``J`` of d x / d p carried through the (linear) operator in one pass: d y / d p."""
        g, taus, w = self.bank(theta)
        if g == 0.0:
            return J
        J = np.ascontiguousarray(J, dtype=np.float64)
        return _creep_cols(J, np.exp(-sample_time(t) / taus), w, g)

    def online(self, theta, base=None):
        g, taus, w = self.bank(theta)
        return CreepInverse(g, taus, w, self.dt)

    def start(self, t, u, y, residual):
        if self.form == "lags":
            return _lags_start(np.asarray(t, float), np.asarray(y, float) - residual, np.asarray(residual, float),
                               self.tau_max)
        # residual ≈ −gain · creep_term(x) with x ≈ the base model's output = y − residual.
        b = creep_term(np.asarray(t, float), np.asarray(y, float) - residual)
        b = b - b.mean()
        den = float(b @ b)
        if den <= 0:
            return {}
        return {"gain": float(-b @ (residual - residual.mean()) / den)}

    def signature(self, t, u, residual, dt):
        hs = [h for h in holds(u, dt, min_seconds=1.0) if h[2] != 0.0]
        if not hs:
            return 0.0, "no holds of at least 1 s after a step in this record, so creep cannot be seen directly"
        slopes, fits = [], []
        for a, b, step in hs:
            tt = (np.arange(b - a) + 1) * dt
            m = tt >= 0.05  # the base's own fast relaxation is over by then
            if m.sum() < 10:
                continue
            lt = np.log10(tt[m])
            r = residual[a:b][m]
            A = np.vstack([np.ones_like(lt), lt]).T
            coef, *_ = np.linalg.lstsq(A, r, rcond=None)
            rr = r - A @ coef
            r2 = 1.0 - float(rr @ rr) / max(float(((r - r.mean()) ** 2).sum()), 1e-300)
            slopes.append(coef[1] / step)
            fits.append(max(r2, 0.0))
        if not slopes:
            return 0.0, "holds too short to see creep"
        s = np.array(slopes)
        same = float(np.mean(np.sign(s) == np.sign(np.median(s))))
        score = float(np.clip(np.median(fits) * (2 * same - 1), 0.0, 1.0))
        per_decade = float(np.median(np.abs(s))) * 1e9
        return score, (f"after each step the residual keeps moving the same way relative to the step for seconds, "
                       f"linearly in log time (median R² {np.median(fits):.2f} over {len(slopes)} holds, "
                       f"{per_decade:.3g} nm per volt of step per decade of time, consistent in {same:.0%})")


def _lags_start(t: np.ndarray, x: np.ndarray, residual: np.ndarray, tau_max: float = TAUS[-1]
                ) -> dict[str, float]:
    """The lags form's start: the pair of :data:`TAUS` whose lags explain the residual best by least squares.

    residual ≈ −Σ_j g_j (x − c_j) is linear in the two gains for a fixed pair of time constants, so every pair is
    one 2 × 2 solve on the Gram matrix of all the bank's columns (formed once). Pairs whose gains differ in sign
    are not a creep with a share in [0, 1] and are skipped. The two lags start distinct and each with at least
    :data:`MIN_START_SHARE` of the creep: with one lag alone (share 0 or 1, or τ1 = τ2) the other's time constant
    has no gradient, and a base fitted without creep has taken up part of it — its δ terms relax like a fast lag —
    so the residual may show one lag where the joint fit needs two (a two-lag record, τ = 0.08 and 2.5 s, fitted
    from the one lag its residual showed ended with that lag's share at 1 and the other on its bound, 6.9× the
    noise; from two distinct lags, each with half the creep, it reached the noise).
    """
    m = int(np.searchsorted(TAUS, tau_max * (1 + 1e-9), side="right"))  # the lags within the bound
    D = (x[None, :] - creep_lags(t, x, TAUS[:m])).T  # (n, m): what each lag falls short of the displacement
    D = D - D.mean(axis=0)
    r = residual - residual.mean()
    G = D.T @ D
    b = -(D.T @ r)
    best: tuple[float, dict[str, float] | None] = (0.0, None)
    for i in range(m):
        for j in range(i + 1, m):
            A = G[np.ix_([i, j], [i, j])]
            det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
            if not det > 1e-12 * A[0, 0] * A[1, 1]:
                continue
            g = np.linalg.solve(A, b[[i, j]])
            if g[0] * g[1] < 0:
                continue
            removed = float(b[i] * g[0] + b[j] * g[1])  # the squared error the pair removes
            tot = float(g[0] + g[1])
            if removed > best[0] and tot != 0.0:
                share = float(np.clip(g[0] / tot, MIN_START_SHARE, 1.0 - MIN_START_SHARE))
                best = (removed, {"gain": tot, "tau1": float(TAUS[i]), "tau2": float(TAUS[j]), "share": share})
    return best[1] or {}


class CreepInverse(OnlineEffect):
    """The creep operator inverted exactly, sample by sample (controllers).

    With the lags updated by the new sample, c_i ← a_i·c_i + (1 − a_i)·x, the output is
    y = x − g·N·Σ w_i·a_i·(x − c_i) (c_i before the update, N = n/PER_DECADE), linear in x:
    x = (y − g·N·Σ w_i a_i c_i) / (1 − g·N·Σ w_i a_i). The lags are then driven by the recovered x, so the
    inverse follows the stage's own creep history.

    In a compensation's prediction chain (:meth:`forward`, after a delay), the target reads the lags as they
    will be when the previewed sample arrives: the measured lags plus what the model predicts they move over the
    preview (lags driven by the undelayed minus the delayed prediction; the lags are linear). Without it the
    target inverted with the lags of now: 5-7 nm off its own model with a 1.5 ms delay on a 30 Hz sine.
    """

    name = "creep"
    predictive = True

    def __init__(self, g: float, taus: np.ndarray, w: np.ndarray, dt: float) -> None:
        """The operator y = x − g · Σ w_i (x − c_i) with lags of time constants ``taus`` (:meth:`Creep.bank`)."""
        taus = np.asarray(taus, dtype=np.float64)
        self._a = np.exp(-dt / taus)
        self._wa = np.asarray(w, dtype=np.float64) * self._a
        self._g = float(g)
        self._den = 1.0 - self._g * float(self._wa.sum())
        if not self._den > 0.05:  # g·Σ w a ≥ 0.95: the operator is not invertible per sample
            raise ValueError(f"creep gain {g:g} (all lags) is too large to invert per sample")
        self._c = np.zeros(taus.size)
        self._cz = np.zeros(taus.size)  # lags driven by the chain's predicted measurement
        self._cw = np.zeros(taus.size)  # ... and by the prediction without delays (preview ahead)

    def reset(self, y, u):
        self._c[:] = y  # at rest the lags sit at the displacement: no creep deficit

    def start(self, x, u):
        self._cz[:] = self._cw[:] = x

    def forward(self, z, w, u, first):
        a, g = self._a, self._g
        yz = z - g * float(self._wa @ (z - self._cz))
        yw = w - g * float(self._wa @ (w - self._cw))
        self._cz = a * self._cz + (1.0 - a) * z
        self._cw = a * self._cw + (1.0 - a) * w
        return yz, yw

    def _inner(self, y: float, c: np.ndarray | None = None) -> float:
        c = self._c if c is None else c
        return (y - self._g * float(self._wa @ c)) / self._den

    def measure(self, y, u):
        x = self._inner(y)
        self._c = self._a * self._c + (1.0 - self._a) * x
        return x

    def target(self, r, u):
        return self._inner(r, self._c + (self._cw - self._cz))
