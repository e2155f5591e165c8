"""Physical forms of effects, deliberately unlike :mod:`hyst_model.effects`' parameterisations.

Each form is ``form(ctx, amp) -> (u_applied, y)`` acting on the clean record; ``amp`` in [0, 1] is the effect's
strength, which :mod:`.cases` calibrates to a target size (RMS change of the output over the noise σ). Input-side
forms change the voltage the hysteresis sees (the truth is re-simulated); output-side forms act on the clean
displacement.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.signal import cont2discrete, fftconvolve, lfilter

__all__ = ["Ctx", "FORMS", "LIBRARY_NAME"]


@dataclass
class Ctx:
    """What a form may use: time, input, the truth's simulator, the clean output, the stroke, a private rng draw."""

    t: np.ndarray
    u: np.ndarray
    simulate: Callable[[np.ndarray], np.ndarray]
    x: np.ndarray
    span: float
    draw: dict


def _frac_delay(v: np.ndarray, d: float) -> np.ndarray:
    k = np.arange(v.size) - d
    return np.interp(k, np.arange(v.size), v, left=v[0])


def _mode(x: np.ndarray, dt: float, fn: float, zeta: float, then: tuple[float, float] | None = None) -> np.ndarray:
    """x through ω²/(s² + 2ζωs + ω²) behind a zero-order hold; ``then = (fn2, zeta2)``: a second mode after it, the
    cascade discretised as one system (one hold: the stage sits between one DAC and one ADC)."""
    w = 2 * np.pi * fn
    num, den = np.array([w * w]), np.array([1.0, 2 * zeta * w, w * w])
    if then is not None:
        w2 = 2 * np.pi * then[0]
        num, den = np.array([w * w * w2 * w2]), np.polymul(den, [1.0, 2 * then[1] * w2, w2 * w2])
    numd, dend, _ = cont2discrete((num, den), dt, method="zoh")
    x0 = x[0]
    return x0 + lfilter(np.ravel(numd), dend, x - x0)


def creep_log(c, a):            # log law after every input change (superposed step responses), per decade
    du = np.diff(c.u, prepend=c.u[0])
    t = c.t - c.t[0]
    gain = c.span / max(np.ptp(c.u), 1e-300)
    kernel = np.log10(1.0 + t / c.draw["tau"])
    return c.u, c.x + a * 0.05 * gain * fftconvolve(du, kernel)[: t.size]


def creep_lags(c, a):           # two first-order lags with static gain (the DC gain grows too)
    dt = c.t[1] - c.t[0]
    y = c.x.copy()
    for tau, w in ((c.draw["tau1"], 0.6), (c.draw["tau2"], 0.4)):
        al = np.exp(-dt / tau)
        lag = lfilter([1 - al], [1, -al], c.x - c.x[0], zi=[0.0])[0]
        y += a * 0.1 * w * lag
    return c.u, y


def asym_sensor(c, a):          # even nonlinearity of the sensor around mid-stroke
    xm = 0.5 * (c.x.min() + c.x.max())
    return c.u, c.x + a * 0.1 * (c.x - xm) ** 2 / (0.5 * c.span)


def asym_kink(c, a):            # the stage stiffens above a level: gain kink
    # the level lies within the stroke the record covers: one above it (at 0.4-0.7 of the full stroke, for a
    # record of a third of it) made a case labelled with an effect the record never shows (size 0: 8 of 34)
    xk = c.x.min() + c.draw["at"] * np.ptp(c.x)
    return c.u, c.x - a * 0.2 * np.maximum(c.x - xk, 0.0)


def mode1(c, a):                # one lightly damped mode, a share of the motion passes it
    m = _mode(c.x, c.t[1] - c.t[0], c.draw["fn"], c.draw["zeta"])
    return c.u, c.x + a * (m - c.x)


def mode2(c, a):                # two modes in cascade, behind one hold
    # (each mode discretised on its own put a second sample of delay between them, which no stage has)
    dt = c.t[1] - c.t[0]
    m = _mode(c.x, dt, c.draw["fn"], c.draw["zeta"], then=(c.draw["fn"] * c.draw["ratio"], c.draw["zeta"]))
    return c.u, c.x + a * (m - c.x)


def delay_in(c, a):             # transport delay of the voltage, fractional samples
    d = 0.3 + a * c.draw["dmax"]
    ud = _frac_delay(c.u, d)
    return ud, c.simulate(ud)


def delay_out(c, a):            # sensor/readout latency, fractional samples
    return c.u, _frac_delay(c.x, 0.3 + a * c.draw["dmax"])


def drift_lin(c, a):
    return c.u, c.x + a * 0.05 * c.span * (c.t - c.t[0]) / (c.t[-1] - c.t[0])


def drift_warm(c, a):           # exponential warm-up
    return c.u, c.x + a * 0.05 * c.span * (1.0 - np.exp(-(c.t - c.t[0]) / c.draw["tau"]))


def drift_slow(c, a):           # slow periodic (thermal cycling), period longer than the record
    T = c.draw["period"] * (c.t[-1] - c.t[0])
    return c.u, c.x + a * 0.05 * c.span * np.sin(2 * np.pi * (c.t - c.t[0]) / T + c.draw["phase"])


def sat_hard(c, a):             # one-sided hard stop near the top
    top = c.x.max() - a * 0.3 * c.span
    return c.u, np.minimum(c.x, top)


def sat_soft(c, a):             # two-sided soft saturation
    xm = 0.5 * (c.x.min() + c.x.max())
    h = 0.5 * c.span
    k = 0.05 + a * 2.0
    return c.u, xm + h * np.tanh(k * (c.x - xm) / h) / np.tanh(k)


def deadzone_in(c, a):          # outside the library: an input dead zone around mid-range (a clamped joint)
    um = 0.5 * (c.u.min() + c.u.max())
    w = a * 0.2 * np.ptp(c.u)
    ud = np.where(np.abs(c.u - um) <= w, um, c.u - np.sign(c.u - um) * w)
    return ud, c.simulate(ud)


def stiffness_change(c, a):     # outside the library: the load changes the gain at a moment in the record
    t0 = c.t[0] + c.draw["at"] * (c.t[-1] - c.t[0])
    xm = c.x.min()
    return c.u, np.where(c.t >= t0, xm + (1.0 - a * 0.3) * (c.x - xm), c.x)


#: form name → (function, library name it should be diagnosed as, or "unexplained")
FORMS: dict[str, tuple[Callable, str]] = {
    "creep_log": (creep_log, "creep"), "creep_lags": (creep_lags, "creep"),
    "asym_sensor": (asym_sensor, "asymmetry"), "asym_kink": (asym_kink, "asymmetry"),
    "mode1": (mode1, "dynamics"), "mode2": (mode2, "dynamics"),
    "delay_in": (delay_in, "delay"), "delay_out": (delay_out, "delay"),
    "drift_lin": (drift_lin, "drift"), "drift_warm": (drift_warm, "drift"), "drift_slow": (drift_slow, "drift"),
    "sat_hard": (sat_hard, "saturation"), "sat_soft": (sat_soft, "saturation"),
    "deadzone_in": (deadzone_in, "unexplained"), "stiffness_change": (stiffness_change, "unexplained"),
}
LIBRARY_NAME = {k: v[1] for k, v in FORMS.items()}


def draw(form: str, rng: np.random.Generator, duration: float, rate: float) -> dict:
    """The form's random shape parameters (not its strength); a mode lies below 0.35 × the sampling ``rate``."""
    return {"tau": rng.uniform(0.05, 1.0), "tau1": rng.uniform(0.02, 0.3), "tau2": rng.uniform(0.5, 3.0),
            "at": rng.uniform(0.4, 0.7), "fn": rng.uniform(120.0, min(700.0, 0.35 * rate)),
            "zeta": rng.uniform(0.02, 0.1),
            "ratio": rng.uniform(1.3, 1.9), "dmax": rng.uniform(2.0, 19.0), "period": rng.uniform(2.0, 4.0),
            "phase": rng.uniform(0, 2 * np.pi)}
