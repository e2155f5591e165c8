"""Transfer functions of the linearised control loop (coefficient arrays in q = z⁻¹, index = power): the stage's
mode, the MBW, the laws' feedback and reference paths, the characteristic polynomials of the raw and of the
compensated loop, and their spectral radius. The loop and its conventions: :mod:`hyst_control.stability`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hyst_model.core import MBWParams
from hyst_model.effects.dynamics_kernels import zoh_matrices

from .dmrac import DMRACGains
from .dppc import DPPCGains
from .errors import ConfigError
from .notch import notch_tf
from .pid import PIDGains

__all__ = ["Resonance", "resonance_tf", "plant_tf", "controller_tf", "reference_tf", "compensated_char",
           "closed_loop_poles", "radii"]


@dataclass(frozen=True)
class Resonance:
    """Stage resonance of the ``dynamics`` effect: natural frequency ``fn`` (Hz), damping ratio ``zeta`` and the
    participation ``part`` (share of the displacement through the mode; 1 = all of it); with ``fn2`` > 0 a second
    mode (``fn2``, ``zeta2``) in cascade after the first, behind the same hold (``dynamics.modes: 2``), the
    participation then being the share through both."""

    fn: float
    zeta: float
    part: float = 1.0
    lag: float = 0.0
    #: The controller's compensation inverts this mode (its Smith predictor and reference inverse run): the loop
    #: is checked as compensated (:func:`compensated_char`), where the mode is left only as a model error.
    compensated: bool = False
    fn2: float = 0.0
    zeta2: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fn) and self.fn > 0 and math.isfinite(self.zeta) and self.zeta > 0):
            raise ConfigError("a resonance needs fn > 0 Hz and zeta > 0")
        if not (math.isfinite(self.part) and 0.0 <= self.part <= 1.0):
            raise ConfigError("a resonance's participation must lie in [0, 1]")
        if not (math.isfinite(self.lag) and 0.0 <= self.lag <= 1.0):
            raise ConfigError("a resonance's sampling lag must lie in [0, 1] samples")
        if self.fn2 != 0.0 and not (math.isfinite(self.fn2) and self.fn2 > 0 and math.isfinite(self.zeta2)
                                    and self.zeta2 > 0):
            raise ConfigError("a second mode needs fn2 > 0 Hz and zeta2 > 0")

    def describe(self) -> str:
        """``350 Hz resonance (zeta 0.04)``, and the second mode when there is one."""
        txt = f"{self.fn:g} Hz resonance (zeta {self.zeta:g})"
        return txt + (f" and the {self.fn2:g} Hz one (zeta {self.zeta2:g}) after it" if self.fn2 > 0 else "")


# -- transfer functions (coefficient arrays in q = z⁻¹, index = power) ---------------------------------------
def resonance_tf(res: Resonance, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH-discretised ω²/(s² + 2ζωs + ω²) with the MBW's timing (y_k responds to the x_k held over period k),
    the share ``1 − part`` passing directly, read ``lag`` samples into the hold (the ``dynamics`` effect's
    :func:`~hyst_model.effects.dynamics_kernels.zoh_matrices`).

    s_k = Φ s_{k−1} + Γa x_{k−1} + Γb x_k (Γa = Γ − Γb; lag 0: Γa = 0), y_k = s_k[0] ⇒
    G(q) = [Γb1 + (Γa1 − Φ22Γb1 + Φ12Γb2) q + (Φ12Γa2 − Φ22Γa1) q²] / [1 − tr Φ·q + det Φ·q²];
    with participation p the reading is (1 − p) + p·G(q). Two modes: G is the cascade's (:func:`_cascade_tf`).
    """
    if res.fn2 > 0:
        num, den = _cascade_tf(res, dt)
    else:
        num, den = _mode_tf(res.fn, res.zeta, res.lag, dt)
    p = float(res.part)
    if p != 1.0:
        num = p * num + (1.0 - p) * den
    return num, den


def _mode_tf(fn: float, zeta: float, lag: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One mode's G(q) of :func:`resonance_tf` (participation 1)."""
    phi, gam, gb = zoh_matrices(fn, zeta, dt, lag)
    ga = gam - gb
    num = np.array([gb[0], ga[0] - phi[1, 1] * gb[0] + phi[0, 1] * gb[1], phi[0, 1] * ga[1] - phi[1, 1] * ga[0]])
    return num, np.array([1.0, -np.trace(phi), np.linalg.det(phi)])


def _cascade_tf(res: Resonance, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Two modes in cascade, discretised as one system (the effect's four-state ``zoh_matrices``): with
    s_k = Φ s_{k−1} + Γa x_{k−1} + Γb x_k and y_k = C s_k, G(q) = C(I − Φq)⁻¹(Γb + Γa q) =
    [z·C adj(zI − Φ)Γb + C adj(zI − Φ)Γa] / det(zI − Φ), whose coefficients in descending z are those in q."""
    from scipy.signal import ss2tf
    phi, gam, gb = zoh_matrices(res.fn, res.zeta, dt, res.lag, (res.fn2, res.zeta2))
    c = np.zeros((1, phi.shape[0]))
    c[0, phi.shape[0] - 2] = 1.0  # the second mode's displacement
    nb, den = ss2tf(phi, gb.reshape(-1, 1), c, np.zeros((1, 1)))
    na, _ = ss2tf(phi, (gam - gb).reshape(-1, 1), c, np.zeros((1, 1)))
    nb, na = np.ravel(nb), np.ravel(na)  # length ns + 1, leading coefficient 0 (strictly proper)
    num = np.r_[nb[1:], 0.0] + na
    return num, np.ravel(den)


def _mu_max(model: MBWParams, u_lo: float, u_hi: float) -> float:
    """Largest incremental gain μ± (4.15)/(4.16) at v_u = 0 over the outputs the input range reaches at rest."""
    ys = [model.zeta1 * u / model.u_scale * (1 - model.delta2) / (1 - model.delta1) for u in (u_lo, u_hi)]
    grid = np.linspace(min(ys + [0.0]), max(ys + [0.0]), 41)
    mus = [model.zeta1 - s * model.psi1 * y - model.alpha1 * abs(y) for y in grid for s in (1.0, -1.0)]
    return max(max(mus), model.zeta1)


def plant_tf(model: MBWParams, dt: float, res: Resonance | None, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Linearised stage u (V) → y (m): g(1 − δ2q)/(1 − δ1q)·G(q), g = μ·y_scale/u_scale."""
    g = mu * model.y_scale / model.u_scale
    num, den = np.array([g, -g * model.delta2]), np.array([1.0, -model.delta1])
    if res is not None:
        rn, rd = resonance_tf(res, dt)
        num, den = np.polymul(num, rn), np.polymul(den, rd)
    return num, den


def _dppc_slope(g: DPPCGains) -> float:
    """f′(0) of the funnel term of (4.13) at a settled funnel (λ_k = λ_{k−1}); χ when h̲ = h̄."""
    lam = g.lambda_inf

    def f(e: float) -> float:
        eps = 0.5 * math.log((lam * g.h_lower + e) / (lam * g.h_upper - e))  # (4.10)
        x = math.exp(2.0 * g.chi * eps)
        return lam * (g.h_upper * x - g.h_lower) / (1.0 + x)

    d = 1e-6 * lam
    return (f(d) - f(-d)) / (2.0 * d)


def controller_tf(algorithm: str, gains, model: MBWParams, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
    """C_y(q): command (V) per measurement y_{k−1} (m) of the linearised law; None for open loop."""
    if algorithm == "open_loop":
        return None
    d1, d2 = model.delta1, model.delta2
    gc = model.zeta1 * model.y_scale / model.u_scale  # the law's μ̂ at rest; cancels against the plant's
    if algorithm == "dppc":
        g = gains or DPPCGains()
        s = _dppc_slope(g)
        if g.ki == 0.0:  # no integral: leave out the (1 − q) it would bring (a pole at z = 1 cancelled by a zero)
            return np.array([s - d1]), gc * np.array([1.0, -d2])
        num = np.array([s - d1 - g.ki, -(s - d1)])
        den = gc * np.polymul([1.0, -d2], [1.0, -1.0])
        return num, den
    if algorithm == "dmrac":
        g = gains or DMRACGains()
        return np.array([g.a_m - d1]), gc * np.array([1.0, -d2])
    if algorithm == "pid":
        g = gains or PIDGains()
        a = dt / (g.t_filter + dt)
        # Sum of the terms over a common denominator; a term that is off brings no factor (a cancelled pole on
        # the unit circle would read as instability).
        num, den = np.array([-g.kp]), np.array([1.0])
        if g.ki > 0.0:  # − K_i·Δt/(1 − q)
            den = np.array([1.0, -1.0])
            num = _add(np.polymul(num, den), [-g.ki * dt])
        if g.kd > 0.0:  # − a·K_d/Δt·(1 − q)/(1 − (1 − a)q)
            filt = np.array([1.0, -(1.0 - a)])
            num = _add(np.polymul(num, filt), np.polymul(-a * g.kd / dt * np.array([1.0, -1.0]), den))
            den = np.polymul(den, filt)
        if g.notch_fn > 0.0:  # the notch on the command (hyst_control.notch): in both paths, one denominator
            nn, nd = notch_tf(g.notch_fn, g.notch_zeta_zero, g.notch_zeta_pole, dt)
            num, den = np.convolve(num, nn), np.convolve(den, nd)
        return num, den
    raise ConfigError(f"no linearisation for algorithm {algorithm!r}")


def reference_tf(algorithm: str, gains, model: MBWParams, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """C_r(q): command (V) per target r_k (m) of the linearised law, over the same denominator as
    :func:`controller_tf` (both paths of one law share its states: separate denominators would add their poles
    twice, a spurious root at z = 1 for an integrator). DPPC and DMRAC: g_c(1 − δ2q)·u = (1 − q·c(q))·r + …,
    c = f′(0) − ki/(1 − q) (DPPC, (4.10)–(4.14)) or a_m (DMRAC, (5.24)); PID: K_p + K_i·Δt/(1 − q) (its derivative
    acts on the measurement only)."""
    c = controller_tf(algorithm, gains, model, dt)
    if c is None:
        raise ConfigError(f"algorithm {algorithm!r} has no feedback loop to check")
    den = c[1]
    if algorithm == "dppc":
        g = gains or DPPCGains()
        s = _dppc_slope(g)
        return (np.array([1.0, -s]) if g.ki == 0.0 else np.array([1.0, -1.0 - s + g.ki, s])), den
    if algorithm == "dmrac":
        return np.array([1.0, -(gains or DMRACGains()).a_m]), den
    g = gains or PIDGains()  # pid (controller_tf refused anything else)
    num = np.array([g.kp + g.ki * dt, -g.kp]) if g.ki > 0.0 else np.array([g.kp])
    if g.kd > 0.0:  # the derivative's filter is in the common denominator
        num = np.convolve(num, [1.0, -(1.0 - dt / (g.t_filter + dt))])
    if g.notch_fn > 0.0:
        num = np.convolve(num, notch_tf(g.notch_fn, g.notch_zeta_zero, g.notch_zeta_pole, dt)[0])
    return num, den


def _inverted_mode(res: Resonance, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The mode as the compensation inverts it: ``(num, den, late)``, as identified (late 0) or — when that has no
    stable inverse and the mode is read about a sample late — the lag-0 mode read one sample late (late 1), as
    :meth:`~hyst_model.effects.dynamics.DynamicsEffect.online` decides."""
    nh, dh = resonance_tf(res, dt)
    zeros = np.roots(np.trim_zeros(nh, "b")) if np.count_nonzero(nh) > 1 else np.zeros(0)
    if abs(nh[0]) > 1e-9 and (zeros.size == 0 or np.max(np.abs(zeros)) < 0.999):
        return nh, dh, 0
    nh, dh = resonance_tf(replace(res, lag=0.0), dt)
    return nh, dh, 1


def compensated_char(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance, stage: Resonance,
                     mu: float) -> tuple[np.ndarray, np.ndarray]:
    """Characteristic polynomial A(q) − γ·B(q) of the loop with the mode ``res`` compensated, on a stage whose mode
    is ``stage`` (coefficients in q).

    The compensation (:class:`~hyst_model.effects.dynamics_online.SeriesResonanceInverse`) feeds the law the
    Smith-corrected measurement y₁ = y − Ĥx̂ + x̂ and the target x* = (r − F(q)x̂)/d̂, where x̂ = G(q)u is the base
    model's prediction, Ĥ = d̂ + F(q) the model's mode (d̂ its feed-through, F strictly causal) and the stage reads
    y = γ·H(q)·G(q)·u. With the law u = C_r(q)·x* + q·C_y(q)·y₁ (one denominator L for both paths,
    :func:`reference_tf`; numerators R and Y) the loop is 1 = [−C_r·F/d̂ + q·C_y·(γH − Ĥ + 1)]·G, i.e. A − γB = 0:

    A = L·d̂·Dh·Dt·Gd + R·(Nh − d̂·Dh)·Dt·Gn + d̂·q·Y·Gn·(Nh·Dt − Dh·Dt),  B = d̂·q·Y·Gn·Nt·Dh

    (N/D: numerator and denominator of Ĥ (h), of the stage's mode (t) and of G). A mode the compensation reads a
    sample late (:func:`_inverted_mode`) enters the predictor as q·Nh. With the stage's mode equal to the model's and
    γ = 1 the poles are the law's error poles, the zeros of Ĥ (the inverse's zero dynamics) and the mode's own
    poles: the mode is gone from the loop, which only a mismatch brings back. (The slow mismatch that drives the
    inverse's state, 0.05 s, is left out: it acts far below the mode.)
    """
    rn, den = reference_tf(algorithm, gains, model, dt)
    yn = controller_tf(algorithm, gains, model, dt)[0]  # type: ignore[index]  # not None: reference_tf checked
    gn, gd = plant_tf(model, dt, None, mu)
    nh, dh, late = _inverted_mode(res, dt)
    nt, dst = resonance_tf(stage, dt)
    d = float(nh[0])
    m = np.convolve  # products in q (np.polymul strips a leading zero coefficient: it would drop a factor q)
    q = np.array([0.0, 1.0])
    qd = np.r_[np.zeros(late), 1.0]  # the predictor compares with the model's reading that many samples late
    a = _add(_add(d * m(m(den, m(gd, dh)), dst), m(m(rn, _add(nh, -d * dh)), m(dst, gn))),
             d * m(m(q, m(yn, gn)), _add(m(m(qd, nh), dst), -m(dh, dst))))
    b = d * m(m(q, m(yn, gn)), m(nt, dh))
    return a, b


def _add(a, b) -> np.ndarray:
    """Sum of two coefficient arrays in q (index = power of q)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    n = max(a.size, b.size)
    return np.pad(a, (0, n - a.size)) + np.pad(b, (0, n - b.size))


def _char(cn, cd, pn, pd, gamma: float) -> np.ndarray:
    a = np.polymul(cd, pd)
    b = np.concatenate(([0.0], np.polymul(cn, pn)))  # one sample of delay: q·C·P
    n = max(a.size, b.size)
    return np.pad(a, (0, n - a.size)) - gamma * np.pad(b, (0, n - b.size))


def closed_loop_poles(cn, cd, pn, pd, gamma: float = 1.0) -> np.ndarray:
    """Poles z of 1 − γ·q·C(q)·P(q) = 0 (coefficients in q; multiplied by zⁿ they are a polynomial in z)."""
    return np.roots(np.trim_zeros(_char(cn, cd, pn, pd, gamma), "b"))


def radii(a, b, gammas) -> np.ndarray:
    """Spectral radius of the roots of A(q) − γ·B(q) = 0 (as poles z = 1/q) for each γ in ``gammas``."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    n = max(a.size, b.size)
    a, b = np.pad(a, (0, n - a.size)), np.pad(b, (0, n - b.size))
    g = np.atleast_1d(np.asarray(gammas, dtype=np.float64))
    coef = (a[None, :] - g[:, None] * b[None, :]) / a[0]  # monic: a[0] = leading coefficient, never γ-dependent
    d = n - 1
    if d == 0:
        return np.zeros(g.size)
    comp = np.zeros((g.size, d, d))
    comp[:, 0, :] = -coef[:, 1:]
    comp[:, np.arange(1, d), np.arange(d - 1)] = 1.0
    return np.max(np.abs(np.linalg.eigvals(comp)), axis=1)
