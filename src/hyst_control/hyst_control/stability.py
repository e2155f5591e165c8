"""Stability of the linearised control loop against an identified stage resonance, and derated gains.

A piezo stage's flexure resonance (model effect ``dynamics``: fn, ζ) sits after the hysteresis. The thesis's
laws are one-step inversions of the MBW (3.21): with a perfect model their error obeys e_k = χ·e_{k−1} (DPPC,
(4.17)–(4.21)) or e_k = a_m·e_{k−1} (DMRAC, (5.40)), i.e. a loop gain of δ1 − χ per sample, far too high in
front of a lightly damped 350 Hz mode sampled at 2 kHz. This module forms the discrete closed loop and checks it.

Loop, per sample k (SI; q = z⁻¹):

* controller, linearised at rest (e = 0, ν ≈ 0, v_u ≈ 0): u = C_r·r + C_y(q)·y_{k−1} — the law sees the newest
  measurement, one sample old (the loop's one sample of delay);
* hysteresis (3.21) linearised at a hold: x_k = δ1·x_{k−1} + g·(u_k − δ2·u_{k−1}), g = μ·y_scale/u_scale with μ the
  local incremental gain (4.15)/(4.16) at v_u = 0;
* resonance, exact ZOH (the sim's and the ``dynamics`` effect's ``hold: zoh``): s_k = Φ·s_{k−1} + Γ·x_k, y_k = s_k[0],
  unit DC gain.

Characteristic polynomial: den_C·den_P − γ·q·num_C·num_P, with γ a gain error between the stage and the model
(γ = 1 nominal). ``stable`` = spectral radius < 1 at γ = 1; the gain margins are the γ > 1 (up) and γ < 1 (down)
at which a pole reaches the unit circle; ``robust`` = stable for every γ in [1/GM, GM].

Controller linearisations (model units, then ÷ g_c = μ̂·y_scale/u_scale, ν convention ν_k = u_k − δ2·u_{k−1}):

* DPPC (4.10)–(4.14): y_r = r_k − δ1·y_{k−1} + f(e_{k−1}) − z, f the funnel term λ(h̄e^{2χε} − h̲)/(1 + e^{2χε})
  with slope s = f′(0) (= χ when h̲ = h̄), z = ki·Σe: C_y = [(s − δ1)(1 − q) − ki] / [g_c(1 − δ2q)(1 − q)].
* DMRAC (5.24)–(5.25) with the estimates frozen (κ small: adaptation is slow): C_y = (a_m − δ1)/[g_c(1 − δ2q)].
* PID (:class:`hyst_control.pid.PID`): C_y = −K_p − K_i·Δt/(1 − q) − a·K_d/Δt·(1 − q)/(1 − (1 − a)q).
* open loop: no feedback; stable whenever the stage is (ζ > 0).

For DPPC and DMRAC the model's gain cancels (the laws invert it), so the check does not depend on μ; for PID
the largest μ over the stroke is used (the worst case for a gain margin).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hyst_model.core import MBWParams
from hyst_model.effects.dynamics_kernels import zoh_matrices

from .dmrac import DMRACGains
from .dppc import DPPCGains
from .errors import ConfigError
from .pid import PIDGains

__all__ = ["Resonance", "identified_resonance", "LoopCheck", "StabilityVerdict", "StabilityError", "POLICIES",
           "resonance_tf", "controller_tf", "plant_tf", "closed_loop_poles", "check_loop", "derate", "guard"]

POLICIES = ("derate", "warn", "refuse")
_G_MAX = 1e3  # gain margins are searched up to this factor (60 dB); beyond it they are reported as inf


class StabilityError(ConfigError):
    """The configured gains make the loop unstable against the identified resonance and the policy refuses."""


@dataclass(frozen=True)
class Resonance:
    """Stage resonance of the ``dynamics`` effect: natural frequency ``fn`` (Hz), damping ratio ``zeta`` and the
    participation ``part`` (share of the displacement through the mode; 1 = all of it)."""

    fn: float
    zeta: float
    part: float = 1.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fn) and self.fn > 0 and math.isfinite(self.zeta) and self.zeta > 0):
            raise ConfigError("a resonance needs fn > 0 Hz and zeta > 0")
        if not (math.isfinite(self.part) and 0.0 <= self.part <= 1.0):
            raise ConfigError("a resonance's participation must lie in [0, 1]")
        if not (math.isfinite(self.lag) and 0.0 <= self.lag <= 1.0):
            raise ConfigError("a resonance's sampling lag must lie in [0, 1] samples")


def identified_resonance(effects, values) -> Resonance | None:
    """The stage resonance a model holds: ``dynamics`` in ``effects`` with ``dynamics.fn`` and ``dynamics.zeta``
    in ``values`` (SI); None when it has none. The one reading the node, ``hyst track`` and the benches share."""
    if "dynamics" not in effects:
        return None
    fn, zeta = values.get("dynamics.fn"), values.get("dynamics.zeta")
    part = values.get("dynamics.part", 1.0)  # files from before the participation: the whole motion
    lag = values.get("dynamics.lag", 0.0)    # ... and before the sampling lag: read at the end of the hold
    return Resonance(float(fn), float(zeta), float(part), float(lag)) if fn and zeta else None


@dataclass(frozen=True)
class LoopCheck:
    """Result of :func:`check_loop`: spectral radius at the nominal gain, gain margins (factors), poles."""

    algorithm: str
    spectral_radius: float
    gain_margin_up: float
    gain_margin_down: float
    required_margin: float
    poles: tuple = field(default=(), repr=False, compare=False)

    @property
    def stable(self) -> bool:
        return self.spectral_radius < 1.0

    @property
    def robust(self) -> bool:
        """Stable for every stage/model gain ratio in [1/GM, GM], GM = ``required_margin``."""
        return (self.stable and self.gain_margin_up >= self.required_margin
                and self.gain_margin_down <= 1.0 / self.required_margin)

    def describe(self) -> str:
        up = "inf" if math.isinf(self.gain_margin_up) else f"{20 * math.log10(self.gain_margin_up):.1f} dB"
        return f"spectral radius {self.spectral_radius:.3f}, gain margin {up}"


@dataclass(frozen=True)
class StabilityVerdict:
    """What :func:`guard` decided: the gains to run, both checks, what was changed and a sentence."""

    algorithm: str
    gains: object
    configured: LoopCheck | None
    running: LoopCheck | None
    derated: tuple = ()      # ((name, configured value, running value), ...)
    warn: bool = False
    message: str = ""


# -- transfer functions (coefficient arrays in q = z⁻¹, index = power) ---------------------------------------
def resonance_tf(res: Resonance, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH-discretised ω²/(s² + 2ζωs + ω²) with the MBW's timing (y_k responds to the x_k held over period k),
    the share ``1 − part`` passing directly, read ``lag`` samples into the hold (the ``dynamics`` effect's
    :func:`~hyst_model.effects.dynamics_kernels.zoh_matrices`).

    s_k = Φ s_{k−1} + Γa x_{k−1} + Γb x_k (Γa = Γ − Γb; lag 0: Γa = 0), y_k = s_k[0] ⇒
    G(q) = [Γb1 + (Γa1 − Φ22Γb1 + Φ12Γb2) q + (Φ12Γa2 − Φ22Γa1) q²] / [1 − tr Φ·q + det Φ·q²];
    with participation p the reading is (1 − p) + p·G(q).
    """
    phi, gam, gb = zoh_matrices(res.fn, res.zeta, dt, res.lag)
    ga = gam - gb
    num = np.array([gb[0], ga[0] - phi[1, 1] * gb[0] + phi[0, 1] * gb[1], phi[0, 1] * ga[1] - phi[1, 1] * ga[0]])
    den = np.array([1.0, -np.trace(phi), np.linalg.det(phi)])
    p = float(res.part)
    if p != 1.0:
        num = p * num + (1.0 - p) * den
    return num, den


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
        return num, den
    raise ConfigError(f"no linearisation for algorithm {algorithm!r}")


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


def _radii(cn, cd, pn, pd, gammas) -> np.ndarray:
    """Spectral radius for each γ in ``gammas`` at once (eigenvalues of a stack of companion matrices)."""
    a = np.polymul(cd, pd)
    b = np.concatenate(([0.0], np.polymul(cn, pn)))
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


def _radius(cn, cd, pn, pd, gamma: float) -> float:
    return float(_radii(cn, cd, pn, pd, [gamma])[0])


def _margin(cn, cd, pn, pd, upward: bool) -> float:
    """First γ (scanning away from 1) where a pole reaches |z| = 1, refined by bisection; inf/0 if none."""
    grid = np.geomspace(1.0, _G_MAX if upward else 1.0 / _G_MAX, 121)
    bad = np.nonzero(_radii(cn, cd, pn, pd, grid) >= 1.0)[0]
    if bad.size == 0:
        return math.inf if upward else 0.0
    lo, hi = grid[bad[0] - 1], grid[bad[0]]
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if _radius(cn, cd, pn, pd, mid) >= 1.0 else (mid, hi)
    return float(hi)


def check_loop(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance | None,
               gain_margin: float = 2.0, v_range: tuple[float, float] = (0.0, 150.0)) -> LoopCheck:
    """Spectral radius and gain margins of the linearised closed loop (see the module docstring).

    Parameters
    ----------
    algorithm : str
        ``dppc``, ``dmrac``, ``pid`` or ``open_loop``.
    gains : DPPCGains, DMRACGains, PIDGains or None
        None = the defaults.
    model : MBWParams
        The controller's stage model (δ1, δ2, scaling; μ for PID).
    dt : float
        Sample period (s).
    res : Resonance or None
        Identified resonance after the hysteresis; None = the MBW alone.
    gain_margin : float
        Required margin (factor, both ways) for :attr:`LoopCheck.robust`.
    v_range : tuple of float
        Command range (V), for the worst-case μ of the PID check.
    """
    if not gain_margin >= 1.0:
        raise ConfigError("gain_margin must be >= 1")
    if algorithm == "pid":
        mu = _mu_max(model, *v_range)
    else:
        mu = model.zeta1  # the model-based laws divide by the same μ: only the ratio (γ) matters
    pn, pd = plant_tf(model, dt, res, mu)
    c = controller_tf(algorithm, gains, model, dt)
    if c is None:
        rad = float(np.max(np.abs(np.roots(pd)))) if pd.size > 1 else 0.0
        return LoopCheck(algorithm, rad, math.inf, 0.0, gain_margin, tuple(np.roots(pd)))
    cn, cd = c
    poles = closed_loop_poles(cn, cd, pn, pd)
    rad = float(np.max(np.abs(poles)))
    up = _margin(cn, cd, pn, pd, True) if rad < 1 else 1.0
    down = _margin(cn, cd, pn, pd, False) if rad < 1 else 1.0
    return LoopCheck(algorithm, rad, up, down, gain_margin, tuple(poles))


def _robust_fast(algorithm, gains, model, dt, res, gm, v_range) -> bool:
    """Stable on a 13-point grid of γ in [1/GM, GM] (the derating search; the result is then checked exactly)."""
    mu = _mu_max(model, *v_range) if algorithm == "pid" else model.zeta1
    pn, pd = plant_tf(model, dt, res, mu)
    c = controller_tf(algorithm, gains, model, dt)
    if c is None:  # only closed loops are derated (_DERATED)
        raise ConfigError(f"algorithm {algorithm!r} has no feedback loop to check")
    cn, cd = c
    return bool(np.all(_radii(cn, cd, pn, pd, np.geomspace(1.0 / gm, gm, 13)) < 1.0))


def _candidate(algorithm: str, gains, t: float):
    """Gains derated by t ∈ [0, 1] (0 = as configured): DPPC χ → 0.995 (ki shrunk with 1 − χ), DMRAC a_m → 0.995
    (slower error poles, (4.21), (5.40)), PID every gain × 10^(−4t)."""
    if algorithm == "dppc":
        chi = gains.chi + t * (0.995 - gains.chi) if gains.chi < 0.995 else gains.chi
        return replace(gains, chi=chi, ki=gains.ki * (1.0 - chi) / (1.0 - gains.chi))
    if algorithm == "dmrac":
        return replace(gains, a_m=gains.a_m + t * (0.995 - gains.a_m) if gains.a_m < 0.995 else gains.a_m)
    f = 10.0 ** (-4.0 * t)
    return replace(gains, kp=gains.kp * f, ki=gains.ki * f, kd=gains.kd * f)


_DERATED = {"dppc": ("chi", "ki"), "dmrac": ("a_m",), "pid": ("kp", "ki", "kd")}


def derate(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance | None, gain_margin: float = 2.0,
           v_range: tuple[float, float] = (0.0, 150.0)):
    """The least-derated gains (see :func:`_candidate`) with a robust loop, or None when none is."""
    if algorithm not in _DERATED:
        return None
    grid = np.linspace(0.0, 1.0, 41)
    ok = [t for t in grid if _robust_fast(algorithm, _candidate(algorithm, gains, t), model, dt, res,
                                          gain_margin, v_range)]
    if not ok:
        return None
    hi = ok[0]
    lo = grid[max(int(np.searchsorted(grid, hi)) - 1, 0)]
    for _ in range(12):  # refine towards the configured gains between the last failing and the first passing t
        mid = 0.5 * (lo + hi)
        if _robust_fast(algorithm, _candidate(algorithm, gains, mid), model, dt, res, gain_margin, v_range):
            hi = mid
        else:
            lo = mid
    return _candidate(algorithm, gains, hi)


def guard(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance | None, policy: str = "derate",
          gain_margin: float = 2.0, v_range: tuple[float, float] = (0.0, 150.0)) -> StabilityVerdict:
    """Check the configured gains against ``res`` and decide what runs.

    ``policy``: ``derate`` (default) runs the least-derated robust gains with a warning; ``warn`` runs the
    configured gains with a warning; ``refuse`` raises :class:`StabilityError` with the reason. Without a
    resonance nothing is checked (the MBW loops are stable by (4.21) and (5.40)).
    """
    if policy not in POLICIES:
        raise ConfigError(f"stability policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if res is None:
        return StabilityVerdict(algorithm, gains, None, None)
    chk = check_loop(algorithm, gains, model, dt, res, gain_margin, v_range)
    where = f"{algorithm} against the {res.fn:g} Hz resonance (zeta {res.zeta:g})"
    if chk.robust:
        return StabilityVerdict(algorithm, gains, chk, chk, message=f"{where}: {chk.describe()}")
    what = "unstable" if not chk.stable else f"short of the {gain_margin:g}x gain margin"
    if policy == "refuse":
        raise StabilityError(f"{where}: the configured gains are {what} ({chk.describe()}); derate them or set "
                             "stability.policy to derate")
    if policy == "warn":
        return StabilityVerdict(algorithm, gains, chk, chk, warn=True,
                                message=f"{where}: configured gains {what} ({chk.describe()}), running them "
                                        "anyway (stability.policy = warn)")
    new = derate(algorithm, gains, model, dt, res, gain_margin, v_range)
    if new is None:
        raise StabilityError(f"{where}: the configured gains are {what} ({chk.describe()}) and no derating of "
                             f"{', '.join(_DERATED.get(algorithm, ()))} reaches a {gain_margin:g}x margin")
    run = check_loop(algorithm, new, model, dt, res, gain_margin, v_range)
    changed = tuple((n, float(getattr(gains, n)), float(getattr(new, n))) for n in _DERATED[algorithm]
                    if getattr(gains, n) != getattr(new, n))
    txt = ", ".join(f"{n} {a:.4g} -> {b:.4g}" for n, a, b in changed)
    return StabilityVerdict(algorithm, new, chk, run, changed, True,
                            f"{where}: configured gains {what} ({chk.describe()}); running derated {txt} "
                            f"({run.describe()})")
