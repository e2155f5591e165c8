"""The series resonance's per-sample inverse for the controllers (:meth:`.dynamics.DynamicsEffect.online`)."""
from __future__ import annotations

import math

import numpy as np

from .dynamics_kernels import zoh_matrices
from .online import OnlineEffect

__all__ = ["SeriesResonanceInverse", "MISMATCH_TAU"]

#: Time constant (s) of the slow measured mismatch that drives the inverse's state (the drift observer's 0.05 s):
#: well below the loop's disturbances, 20 periods of a 400 Hz mode (its fast mismatch stays out of the target).
MISMATCH_TAU = 0.05


class SeriesResonanceInverse(OnlineEffect):
    """The series resonance for controllers: inverted on the reference, predicted out of the measurement.

    * target: the ZOH recursion s_k = Φ s_{k−1} + Γ x_k reads y_k = (Φ s_{k−1})_0 + Γ_0 x_k, so the inner output
      that makes the stage read r_k is x_k = (r_k − (Φ s_{k−1})_0) / Γ_0, with the state driven by the base
      model's prediction of what the applied input achieved (noise-free; a command cut by the slew or range
      limit leaves the state where the stage really is, not where the target wanted it); the inverse's zero
      dynamics are stable where the sampled zero lies inside the unit circle (refused otherwise);
    * measure: a Smith predictor, y + x̂ − H x̂ with x̂ the base model driven by the applied input, so the law
      sees the stage without its resonance plus every model error (no inverse filter on sensor noise).

    With a participation ``part`` < 1 the reading is (1 − part)·x + part·(mode output): the direct share adds
    (1 − part) to the feed-through (x_k = (r_k − part·(Φ s_{k−1})_0) / ((1 − part) + part·Γ_0)) and the
    predictor subtracts part·(H x̂ − x̂). With a sampling lag (``lag`` > 0, :func:`~.dynamics_kernels.zoh_matrices`)
    the state also carries the previous inner output (its Γ − Γ_b share), and the feed-through is Γ_b; a lag that
    puts the sampled zero outside the unit circle is refused like any other.

    ``second = (fn2, zeta2)``: two modes in cascade behind one hold (``dynamics.modes: 2``), the same recursion on
    the four-state system of :func:`~.dynamics_kernels.zoh_matrices` read at the second mode's displacement; its
    inverse exists where the cascade's sampled zeros lie inside the unit circle (refused otherwise, as above).

    ``delay`` (whole samples) reads the mode that many samples late: the reference is previewed by it and the
    predictor compares the measurement with the reading ``delay`` samples old. A lag of one sample is exactly that
    (:meth:`DynamicsEffect.online` uses it: the reading then has no feed-through of x_k, so no inverse of its own).

    The state the target reads is driven by the prediction *plus the slow measured mismatch* m (the reading minus
    the model's, low-passed with :data:`MISMATCH_TAU`; closed loop only, :meth:`observe`). Driven by the prediction
    alone it undid every correction the law made against an offset the model does not know: the law aims the
    Smith-corrected value x̂ + d at the target, the inverse then sees x̂ moved by −d and asks for it back, and the
    stage stays (1 − Γ_0)·d off while the law sees no error (drift + a 391 Hz mode: 8-11x the drift-free level).
    With m ≈ d the inverse's state follows the mode's input as the stage really has it, and at low frequencies
    the stage reads the reference. m starts at 0 (bumpless) and stays 0 in open loop (no sensor).
    """

    name = "dynamics"
    smith = predictive = True

    def __init__(self, fn: float, zeta: float, dt: float, base, part: float = 1.0, lag: float = 0.0,
                 delay: int = 0, second: tuple[float, float] | None = None) -> None:
        phi, g, gb = zoh_matrices(fn, zeta, dt, lag, second)
        ns = phi.shape[0]  # (y1, ẏ1) or, two modes in cascade, (y1, ẏ1, y2, ẏ2)
        self._o = ns - 2  # the state the stage reads: the (last) mode's displacement
        # State z = (s, x_{k−1}): z_k = A z_{k−1} + B x_k reads the mode's s_k = Φ s_{k−1} + (Γ − Γ_b) x_{k−1}
        # + Γ_b x_k (sampling lag, zoh_matrices; lag 0: Γ_b = Γ and x_{k−1} drops out).
        self._A = np.zeros((ns + 1, ns + 1))
        self._A[:ns, :ns], self._A[:ns, ns] = phi, g - gb
        self._B = np.r_[gb, 1.0]
        self._rest = np.zeros(ns + 1)  # at rest under x: every mode's displacement and the last input are x
        self._rest[0:ns:2] = self._rest[ns] = 1.0
        self._part = float(part)
        what = f"a {fn:g} Hz resonance" + (f" with a second at {second[0]:g} Hz" if second is not None else "")
        self._d = (1.0 - self._part) + self._part * float(gb[self._o])  # feed-through of x_k to y_k
        if not abs(self._d) > 1e-9:
            raise ValueError(f"{what} has no direct feed-through at dt = {dt:g} s")
        zeros = np.linalg.eigvals(self._A - self._part * np.outer(self._B, self._A[self._o]) / self._d)
        if np.max(np.abs(zeros)) >= 0.999:
            raise ValueError(f"{what}: its sampled zero lies on or outside the unit circle"
                             + (f" (read {lag:.2f} samples into the hold)" if lag > 0 else "")
                             + ": its inverse would diverge")
        self._pred = base()
        self._s = np.zeros(ns + 1)  # resonance state (and the last input) driven by the base model's prediction
        if delay < 0:
            raise ValueError("the reading's delay must be a whole number of samples >= 0")
        self.preview = delay * dt
        self._read = np.zeros(delay + 1)  # the model's reading, newest first
        self._fs = np.zeros(ns + 1)  # the same driven by the predicted measurement (forward: may be delayed)
        self._m = 0.0  # slow measured mismatch at this effect's output (m), added to what drives _s
        self._innov = math.nan  # the newest reading minus the model's, until observe() takes it
        self._g = min(1.0, dt / MISMATCH_TAU)

    def reset(self, y, u):
        self.start(self._pred.reset(u), u)

    def start(self, x, u):
        self._s[:] = self._fs[:] = x * self._rest
        self._read[:] = x
        self._m, self._innov = 0.0, math.nan

    def forward(self, z, w, u, first):
        p = self._part
        w = w + self._m  # the mode's input as the stage has it (see the class docstring)
        self._s = self._A @ self._s + self._B * w
        self._fs = self._A @ self._fs + self._B * z
        self._read[1:] = self._read[:-1]
        self._read[0] = (1.0 - p) * z + p * float(self._fs[self._o])
        return float(self._read[-1]), (1.0 - p) * w + p * float(self._s[self._o])

    def mismatch(self, e):
        self._innov = e

    def observe(self, x, u):
        if math.isfinite(self._innov):  # a bad sample must not poison the state
            self._m += self._g * (self._innov - self._m)

    def measure(self, y, u):
        x_hat = self._pred.step(u)
        read = self.forward(x_hat, x_hat, u, True)[0]
        self.mismatch(y - read)
        return y - read + x_hat

    def target(self, r, u):
        return (r - self._part * float((self._A @ self._s)[self._o])) / self._d
