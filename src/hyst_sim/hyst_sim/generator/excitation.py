"""Excitations a lab user records, in volts within the actuator's range (seeded)."""
from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

__all__ = ["EXCITATIONS", "excitation"]

EXCITATIONS = ("steps", "sines", "triangles", "noise", "sweep", "mix")


def _steps(t, rng):
    out, k = np.empty_like(t), 0
    while k < t.size:
        hold = int(rng.uniform(0.4, 1.5) / (t[1] - t[0]))
        out[k:k + hold] = rng.uniform(0.05, 0.95)
        k += hold
    return out


def _sines(t, rng):
    n = rng.integers(1, 4)
    f = np.sort(rng.uniform(0.5, 15.0, n))
    a = rng.dirichlet(np.ones(n)) * rng.uniform(0.3, 0.5)
    return 0.5 + sum(ai * np.sin(2 * np.pi * fi * t + rng.uniform(0, 2 * np.pi)) for ai, fi in zip(a, f))


def _triangles(t, rng):
    f = rng.uniform(0.5, 4.0)
    ph = (f * t) % 1.0
    tri = 2.0 * np.abs(2.0 * ph - 1.0) - 1.0                                  # −1..1
    amps = rng.permutation([0.15, 0.3, 0.45])                               # minor loops at three amplitudes
    seg = np.minimum((3 * t / t[-1]).astype(int), 2)
    return 0.5 + amps[seg] * tri


def _noise(t, rng):
    dt = t[1] - t[0]
    sos = butter(4, rng.uniform(2.0, 20.0), fs=1.0 / dt, output="sos")
    x = sosfiltfilt(sos, rng.standard_normal(t.size))
    return 0.5 + 0.4 * x / (np.max(np.abs(x)) + 1e-300)


def _sweep(t, rng):
    f0, f1 = rng.uniform(0.3, 1.0), rng.uniform(20.0, 60.0)
    phase = 2 * np.pi * f0 * t[-1] / np.log(f1 / f0) * (np.exp(t / t[-1] * np.log(f1 / f0)) - 1.0)
    return 0.5 + rng.uniform(0.3, 0.45) * np.sin(phase)


def _mix(t, rng):
    h = t.size // 2
    a, b = rng.choice(["steps", "sines", "triangles", "noise", "sweep"], 2, replace=False)
    return np.r_[_BUILD[a](t[:h], rng), _BUILD[b](t[h:] - t[h], rng)]


_BUILD = {"steps": _steps, "sines": _sines, "triangles": _triangles, "noise": _noise, "sweep": _sweep, "mix": _mix}


def excitation(kind: str, t: np.ndarray, v_min: float, v_max: float, rng: np.random.Generator) -> np.ndarray:
    """Input voltage (V) of the given kind over ``t`` within ``[v_min, v_max]``.

    The shape is built on 0..1 and mapped to the range; the first 0.2 s ramp in from the rest level so no record
    starts with a jump the stage never saw.
    """
    x = np.clip(_BUILD[kind](t, rng), 0.0, 1.0)
    ramp = np.clip(t / 0.2, 0.0, 1.0)
    x = 0.5 + ramp * (x - 0.5)
    return v_min + (v_max - v_min) * x
