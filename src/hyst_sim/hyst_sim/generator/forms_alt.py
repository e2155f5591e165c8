"""Other physical forms of the library's effects, for a family no diagnosis was developed on (``forms="alt"``).

:mod:`.forms` holds the forms the benchmark's families use; these are other shapes of the same physics, each
written from a different law than both :mod:`.forms` and :mod:`hyst_model.effects` — a power-law creep, a
sensor whose gain grows exponentially along the stroke, a mode with a non-collocated zero (an antiresonance
above it), a latency split between the amplifier and the sensor, a random-walk and an accelerating drift, and a
polynomial softening at both ends of the travel. Same interface as :mod:`.forms`: ``form(ctx, amp) -> (u, y)``
with ``amp`` in [0, 1], calibrated to a size by :mod:`.cases`.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.signal import cont2discrete, fftconvolve, lfilter

from .forms import Ctx, _frac_delay

__all__ = ["ALT_FORMS", "ALT_LIBRARY_NAME", "draw_alt"]


def creep_power(c: Ctx, a: float):     # power law after every input change: (1 + t/τ)^γ − 1, γ 0.1–0.3, up to 20 %
    du = np.diff(c.u, prepend=c.u[0])
    t = c.t - c.t[0]
    gain = c.span / max(np.ptp(c.u), 1e-300)
    kernel = (1.0 + t / c.draw["tau"]) ** c.draw["gamma"] - 1.0
    return c.u, c.x + a * 0.2 * gain * fftconvolve(du, kernel)[: t.size] / max(float(kernel[-1]), 1e-300)


def asym_exp(c: Ctx, a: float):        # the sensor's gain grows exponentially towards one end (a gap sensor's 1/d)
    lo, hi = float(c.x.min()), float(c.x.max())
    span = max(hi - lo, 1e-300)
    s = c.draw["bend"] * span          # the length over which the gain grows by e
    z = ((c.x - lo) if c.draw["sign"] > 0 else (hi - c.x)) / s
    big = span / s
    bent = span * (np.expm1(z) - z) / max(float(np.expm1(big) - big), 1e-300)   # convex, 0 → span
    chord = span * z / big                       # the straight line through its ends: a gain the base takes
    return c.u, c.x + a * 0.2 * (bent - chord)


def mode_zero(c: Ctx, a: float):       # a mode with an antiresonance above it (the sensor on another body)
    dt = c.t[1] - c.t[0]
    wp = 2 * np.pi * c.draw["fn"]
    wz = wp * c.draw["ratio"]
    zp, zz = c.draw["zeta"], 0.5 * c.draw["zeta"]
    num = np.array([1.0, 2 * zz * wz, wz * wz]) * (wp * wp / (wz * wz))
    den = np.array([1.0, 2 * zp * wp, wp * wp])
    numd, dend, _ = cont2discrete((num, den), dt, method="zoh")
    x0 = c.x[0]
    m = x0 + lfilter(np.ravel(numd), dend, c.x - x0)
    return c.u, c.x + a * (m - c.x)


def delay_split(c: Ctx, a: float):     # latency in the amplifier and in the sensor, fractional samples each
    d = 0.3 + a * c.draw["dmax"]
    share = c.draw["share"]
    ud = _frac_delay(c.u, share * d)
    return ud, _frac_delay(c.simulate(ud), (1.0 - share) * d)


def drift_walk(c: Ctx, a: float):      # a random walk, low-passed below 0.2–1 Hz (the same course on both records)
    rng = np.random.default_rng(c.draw["walk_seed"])
    dt = c.t[1] - c.t[0]
    w = np.cumsum(rng.standard_normal(c.t.size)) * np.sqrt(dt)
    al = np.exp(-2 * np.pi * c.draw["corner"] * dt)
    w = lfilter([1 - al], [1, -al], w - w[0])
    w = w / max(float(np.max(np.abs(w))), 1e-300)
    return c.u, c.x + a * 0.05 * c.span * w


def drift_quad(c: Ctx, a: float):      # an accelerating drift (a heater ramping up)
    s = (c.t - c.t[0]) / (c.t[-1] - c.t[0])
    return c.u, c.x + a * 0.05 * c.span * s * s


def sat_cubic(c: Ctx, a: float):       # polynomial softening at both ends: x − k·h·((x − xm)/h)³, monotonic
    xm = 0.5 * (c.x.min() + c.x.max())
    h = max(0.5 * float(np.ptp(c.x)), 1e-300)
    z = (c.x - xm) / h
    return c.u, c.x - a * 0.3 * h * z ** 3   # slope 1 − 0.9 a z² > 0 on the record's travel


#: form name → (function, library name it should be diagnosed as)
ALT_FORMS: dict[str, tuple[Callable, str]] = {
    "creep_power": (creep_power, "creep"),
    "asym_exp": (asym_exp, "asymmetry"),
    "mode_zero": (mode_zero, "dynamics"),
    "delay_split": (delay_split, "delay"),
    "drift_walk": (drift_walk, "drift"), "drift_quad": (drift_quad, "drift"),
    "sat_cubic": (sat_cubic, "saturation"),
}
ALT_LIBRARY_NAME = {k: v[1] for k, v in ALT_FORMS.items()}


def draw_alt(rng: np.random.Generator, rate: float) -> dict:
    """The alternative forms' random shape parameters (not their strength)."""
    return {"tau": rng.uniform(0.01, 0.5), "gamma": rng.uniform(0.1, 0.3), "bend": rng.uniform(0.3, 1.5),
            "sign": float(rng.choice([-1.0, 1.0])), "fn": rng.uniform(120.0, min(700.0, 0.3 * rate)),
            "zeta": rng.uniform(0.02, 0.1), "ratio": rng.uniform(1.2, 1.8), "dmax": rng.uniform(2.0, 19.0),
            "share": rng.uniform(0.2, 0.8), "walk_seed": int(rng.integers(0, 2**31)),
            "corner": rng.uniform(0.2, 1.0)}
