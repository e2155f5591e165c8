"""Stability of the linearised control loop against an identified stage resonance, and derated gains.

A piezo stage's flexure resonance (model effect ``dynamics``: fn, ζ) sits after the hysteresis. The thesis's
laws are one-step inversions of the MBW (3.21): with a perfect model DPPC's transformed error obeys
ε_k = χ·ε_{k−1} (4.21) — to first order, with a settled funnel λ and h̲ = h̄, the tracking error too,
e_k ≈ χ·e_{k−1} (the linearisation used here) — and DMRAC's e_k = a_m·e_{k−1} (5.40), i.e. a loop gain of δ1 − χ per
sample, far too high in front of a lightly damped 350 Hz mode sampled at 2 kHz. This module forms the discrete
closed loop and checks it.

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
* PID (:class:`hyst_control.pid.PID`): C_y = −K_p − K_i·Δt/(1 − q) − a·K_d/Δt·(1 − q)/(1 − (1 − a)q), times the
  command notch N(q) when it has one (:mod:`hyst_control.notch`).
* open loop: no feedback; stable whenever the stage is (ζ > 0).

For DPPC and DMRAC the model's gain cancels (the laws invert it), so the check does not depend on μ; for PID
the largest μ over the stroke is used (the worst case for a gain margin).

When the controller's compensation inverts the mode (``Resonance.compensated``: Smith predictor on the
measurement, inverse on the reference) the loop is a different one, :func:`compensated_char`: as identified the
mode is gone from it, and what is checked is a mismatch — the gain error γ as above, for every stage mode within
:data:`MODE_TOLERANCE` of the identified one. Checked against the raw mode instead, generated stage 1008 (314 Hz,
inverted) ran DMRAC derated to a_m 0.91 at 32× its mode-free twin; checked as compensated it tracks at 1×.

PID is model-free: derated it can only be slowed down. :func:`guard` also tries a notch on its command at the
identified mode (:func:`notched`, as commercial piezo controllers offer) and runs it when it keeps more gain; a
notch relies on the identified mode as compensation does, so a notched loop is checked over the same envelope.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hyst_model.core import MBWParams

from .errors import ConfigError
from .loop_tf import (Resonance, _add, _mu_max, closed_loop_poles, compensated_char, controller_tf, plant_tf,
                      radii, reference_tf, resonance_tf)
from .notch import NYQUIST_SHARE

__all__ = ["Resonance", "identified_resonance", "LoopCheck", "StabilityVerdict", "StabilityError", "POLICIES",
           "resonance_tf", "controller_tf", "reference_tf", "plant_tf", "compensated_char", "closed_loop_poles",
           "radii", "check_loop", "derate", "guard", "notched", "MODE_TOLERANCE", "NOTCH_ZETA_POLE"]

POLICIES = ("derate", "warn", "refuse")
_G_MAX = 1e3  # gain margins are searched up to this factor (60 dB); beyond it they are reported as inf


class StabilityError(ConfigError):
    """The configured gains make the loop unstable against the identified resonance and the policy refuses."""


def identified_resonance(effects, values, compensation=None, config=None) -> Resonance | None:
    """The stage resonance a model holds: ``dynamics`` in ``effects`` with ``dynamics.fn`` and ``dynamics.zeta``
    in ``values`` (SI); None when it has none. The one reading the node, ``hyst track`` and the benches share.
    ``compensation`` (a :class:`~hyst_control.compensation.Compensation`): the controller's; when it inverts the
    mode the resonance is marked ``compensated`` (checked as the compensated loop). ``dynamics.modes`` (in
    ``config`` or ``values``) 2: the second mode (``dynamics.fn2``, ``zeta2``) is part of it."""
    if "dynamics" not in effects:
        return None
    fn, zeta = values.get("dynamics.fn"), values.get("dynamics.zeta")
    part = values.get("dynamics.part", 1.0)  # files from before the participation: the whole motion
    lag = values.get("dynamics.lag", 0.0)    # ... and before the sampling lag: read at the end of the hold
    comp = compensation is not None and "dynamics" in getattr(compensation, "names", ())
    if not (fn and zeta):
        return None
    modes = {**values, **(config or {})}.get("dynamics.modes", 1)
    second = {}
    if int(float(modes)) == 2:
        second = {"fn2": float(values["dynamics.fn2"]), "zeta2": float(values["dynamics.zeta2"])}
    return Resonance(float(fn), float(zeta), float(part), float(lag), comp, **second)


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


#: Mode mismatch a compensated loop must tolerate (besides the gain error γ): the stage's fn within ±10 % of the
#: identified one and its ζ within ×/÷ 2. Identification does far better on records with the mode in them (generated
#: 391 Hz stage: fn 0.03-0.25 % off, ζ 1 %); the envelope covers a stage that has warmed or been reloaded since.
MODE_TOLERANCE = (0.10, 2.0)


def _pairs(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance | None, v_range
           ) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """The loop's characteristic polynomials A(q) − γ·B(q): one for the raw loop, or one per stage mode of the
    :data:`MODE_TOLERANCE` envelope when the compensation inverts ``res``; None for open loop."""
    mu = _mu_max(model, *v_range) if algorithm == "pid" else model.zeta1  # model-based laws: μ cancels
    c = controller_tf(algorithm, gains, model, dt)
    if c is None:
        return None
    cn, cd = c
    if res is None:
        pn, pd = plant_tf(model, dt, None, mu)
        return [(np.polymul(cd, pd), np.concatenate(([0.0], np.polymul(cn, pn))))]
    df, kz = MODE_TOLERANCE
    stages = [replace(res, fn=res.fn * f, zeta=res.zeta * z, fn2=res.fn2 * f, zeta2=res.zeta2 * z)
              for f in (1.0, 1.0 - df, 1.0 + df) for z in (1.0, 1.0 / kz, kz)]
    if res.compensated:
        return [compensated_char(algorithm, gains, model, dt, res, st, mu) for st in stages]
    if not _notched(algorithm, gains):  # the raw loop relies on nothing but the gain: the mode as identified
        stages = stages[:1]
    out = []
    for st in stages:  # a notch designed on the identified mode must hold for the stage's mode off it
        pn, pd = plant_tf(model, dt, st, mu)
        out.append((np.polymul(cd, pd), np.concatenate(([0.0], np.polymul(cn, pn)))))
    return out


def _notched(algorithm: str, gains) -> bool:
    return algorithm == "pid" and gains is not None and float(getattr(gains, "notch_fn", 0.0)) > 0.0


def _worst(pairs, gammas) -> np.ndarray:
    return np.max([radii(a, b, gammas) for a, b in pairs], axis=0)


def _margin(pairs, upward: bool) -> float:
    """First γ (scanning away from 1) where a pole reaches |z| = 1 (any of ``pairs``), refined by bisection;
    inf/0 if none."""
    grid = np.geomspace(1.0, _G_MAX if upward else 1.0 / _G_MAX, 121)
    bad = np.nonzero(_worst(pairs, grid) >= 1.0)[0]
    if bad.size == 0:
        return math.inf if upward else 0.0
    lo, hi = grid[bad[0] - 1], grid[bad[0]]
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if _worst(pairs, [mid])[0] >= 1.0 else (mid, hi)
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
        Identified resonance after the hysteresis; None = the MBW alone. When it is ``compensated`` the loop is
        checked as the compensation runs it (:func:`compensated_char`), worst over the stage modes of
        :data:`MODE_TOLERANCE` (radius and margins alike).
    gain_margin : float
        Required margin (factor, both ways) for :attr:`LoopCheck.robust`.
    v_range : tuple of float
        Command range (V), for the worst-case μ of the PID check.
    """
    if not gain_margin >= 1.0:
        raise ConfigError("gain_margin must be >= 1")
    pairs = _pairs(algorithm, gains, model, dt, res, v_range)
    if pairs is None:
        pd = plant_tf(model, dt, res, model.zeta1)[1]
        rad = float(np.max(np.abs(np.roots(pd)))) if pd.size > 1 else 0.0
        return LoopCheck(algorithm, rad, math.inf, 0.0, gain_margin, tuple(np.roots(pd)))
    rads = [radii(a, b, [1.0])[0] for a, b in pairs]
    a, b = pairs[int(np.argmax(rads))]
    poles = np.roots(np.trim_zeros(_add(a, -b), "b"))
    rad = float(max(rads))
    up = _margin(pairs, True) if rad < 1 else 1.0
    down = _margin(pairs, False) if rad < 1 else 1.0
    return LoopCheck(algorithm, rad, up, down, gain_margin, tuple(poles))


def _robust_fast(algorithm, gains, model, dt, res, gm, v_range) -> bool:
    """Stable on a 13-point grid of γ in [1/GM, GM] (the derating search; the result is then checked exactly)."""
    pairs = _pairs(algorithm, gains, model, dt, res, v_range)
    if pairs is None:  # only closed loops are derated (_DERATED)
        raise ConfigError(f"algorithm {algorithm!r} has no feedback loop to check")
    return bool(np.all(_worst(pairs, np.geomspace(1.0 / gm, gm, 13)) < 1.0))


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
#: What the guard may change (reported): the derated gains, and PID's notch.
_CHANGED = dict(_DERATED, pid=("kp", "ki", "kd", "notch_fn", "notch_zeta_zero", "notch_zeta_pole"))
#: Pole damping of the notch the guard places (:func:`notched`): the mode's lightly damped pair replaced by a
#: critically damped one. Wider notches let the linear check keep more gain (ζp 5: a lag pole near fn/10) but
#: slow the loop below the mode; 1 is the widest that adds no pole below the mode's frequency.
NOTCH_ZETA_POLE = 1.0


def _notchable(algorithm: str, gains) -> bool:
    """PID gains without a notch of their own (the guard may place one)."""
    return algorithm == "pid" and gains is not None and not _notched(algorithm, gains)


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


def notched(gains, res: Resonance, dt: float):
    """PID gains with the command notch at the identified mode (:mod:`hyst_control.notch`): zeros at the mode's
    own damping (they cancel its poles), poles at :data:`NOTCH_ZETA_POLE`; None when the rate cannot hold it."""
    if res.fn >= NYQUIST_SHARE * 0.5 / dt:
        return None
    return replace(gains, notch_fn=res.fn, notch_zeta_zero=min(res.zeta, NOTCH_ZETA_POLE),
                   notch_zeta_pole=NOTCH_ZETA_POLE)


def guard(algorithm: str, gains, model: MBWParams, dt: float, res: Resonance | None, policy: str = "derate",
          gain_margin: float = 2.0, v_range: tuple[float, float] = (0.0, 150.0), notch: bool = True
          ) -> StabilityVerdict:
    """Check the configured gains against ``res`` and decide what runs.

    ``policy``: ``derate`` (default) runs the least-derated robust gains with a warning; ``warn`` runs the
    configured gains with a warning; ``refuse`` raises :class:`StabilityError` with the reason. Without a
    resonance nothing is checked (the MBW loops are stable by (4.21) and (5.40)). ``notch`` (PID under
    ``derate``, configured without one): a notch at the identified mode (:func:`notched`) is tried too, and runs
    when it needs less derating (it is then checked for every stage mode of :data:`MODE_TOLERANCE`).
    """
    if policy not in POLICIES:
        raise ConfigError(f"stability policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if res is None:
        return StabilityVerdict(algorithm, gains, None, None)
    chk = check_loop(algorithm, gains, model, dt, res, gain_margin, v_range)
    where = f"{algorithm} against the {res.describe()}"
    if res.compensated:  # the user can tell which loop was judged
        df, kz = MODE_TOLERANCE
        where += (f", compensated (the loop with its inverse, for a stage mode within fn ±{df:.0%}, "
                  f"zeta x/÷{kz:g})")
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
    with_notch = notched(gains, res, dt) if notch and _notchable(algorithm, gains) else None
    if with_notch is not None and check_loop(algorithm, with_notch, model, dt, res, gain_margin, v_range).robust:
        new = with_notch  # the configured gains with the notch: no derating can keep more gain
    else:
        new = derate(algorithm, gains, model, dt, res, gain_margin, v_range)
        alt = derate(algorithm, with_notch, model, dt, res, gain_margin, v_range) if with_notch is not None else None
        if alt is not None and (new is None or alt.kp > new.kp):  # PID's gains derate by one factor: kp tells
            new = alt
    if new is None:
        raise StabilityError(f"{where}: the configured gains are {what} ({chk.describe()}) and no derating of "
                             f"{', '.join(_DERATED.get(algorithm, ()))} reaches a {gain_margin:g}x margin")
    run = check_loop(algorithm, new, model, dt, res, gain_margin, v_range)
    changed = tuple((n, float(getattr(gains, n)), float(getattr(new, n))) for n in _CHANGED[algorithm]
                    if getattr(gains, n) != getattr(new, n))
    txt = ", ".join(f"{n} {a:.4g} -> {b:.4g}" for n, a, b in changed if not n.startswith("notch"))
    if any(n.startswith("notch") for n, _, _ in changed):
        txt += (f"{', ' if txt else ''}with a notch on the command at {new.notch_fn:g} Hz (zeta {new.notch_zeta_zero:g}"
                f" / {new.notch_zeta_pole:g})")
    return StabilityVerdict(algorithm, new, chk, run, changed, True,
                            f"{where}: configured gains {what} ({chk.describe()}); running derated {txt} "
                            f"({run.describe()})")
