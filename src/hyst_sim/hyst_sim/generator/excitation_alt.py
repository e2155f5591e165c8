"""Other excitations a lab user records (seeded), for a family the diagnosis was not developed on.

The benchmark's own excitations (:mod:`.excitation`) all swing about the middle of the actuator's range. These are
the other schedules of hysteresis and creep identification: decaying sines (nested minor loops, as for
first-order reversal curves), staircases up and down (creep after every step), trapezoids (ramps between holds),
random-phase multisines (the Bouc-Wen benchmark's kind) and sine bursts between rests. Each is drawn either over
most of the range or over a part of it (a stage used near one end), the part drawn from ``span_rng`` so that a
fresh record of the same case covers the same part with a new realisation.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ALT_EXCITATIONS", "excitation_alt"]

ALT_EXCITATIONS = ("decay", "staircase", "trapezoid", "multisine", "bursts")


def _decay(t, rng):
    # restarts so the whole record excites; each decays to ~5 % (nested minor loops)
    out, k, dt = np.empty_like(t), 0, t[1] - t[0]
    while k < t.size:
        n = max(1, int(rng.uniform(1.5, 4.0) / dt))   # at least one sample: a coarse sampling still advances
        tt = np.arange(min(n, t.size - k)) * dt
        f = rng.uniform(0.5, 8.0)
        out[k:k + tt.size] = np.exp(-3.0 * tt / (n * dt)) * np.sin(2 * np.pi * f * tt)
        k += tt.size
    return out


def _staircase(t, rng):
    levels = int(rng.integers(4, 11))
    up = np.linspace(-1.0, 1.0, levels)
    seq = np.r_[up, up[-2:0:-1]]                                        # up, then down: a major loop in steps
    out, k, i, dt = np.empty_like(t), 0, 0, t[1] - t[0]
    hold = rng.uniform(0.15, 0.6)
    while k < t.size:
        n = max(1, int(hold * rng.uniform(0.8, 1.2) / dt))
        out[k:k + n] = seq[i % seq.size]
        k, i = k + n, i + 1
    return out


def _trapezoid(t, rng):
    pts, k = [], 0.0
    while k < t[-1]:
        ramp, hold = rng.uniform(0.05, 0.8), rng.uniform(0.1, 0.8)
        nxt = rng.uniform(-1.0, 1.0)
        pts += [(k + ramp, nxt), (k + ramp + hold, nxt)]
        k += ramp + hold
    tp = np.r_[0.0, [p[0] for p in pts]]
    lv = np.r_[0.0, [p[1] for p in pts]]
    return np.interp(t, tp, lv)


def _multisine(t, rng):
    f_max = rng.uniform(10.0, 50.0)
    f0 = 1.0 / min(t[-1], 4.0)                                          # lines every f0 Hz up to f_max
    f = np.arange(f0, f_max, f0)
    x = np.sum(np.sin(2 * np.pi * f[:, None] * t[None, :] + rng.uniform(0, 2 * np.pi, f.size)[:, None]), axis=0)
    return x / (np.max(np.abs(x)) + 1e-300)


def _bursts(t, rng):
    dt, out, k = t[1] - t[0], np.zeros_like(t), 0
    while k < t.size:
        f = rng.uniform(3.0, 30.0)
        n = max(1, int(rng.integers(3, 12) / f / dt))
        rest = max(1, int(rng.uniform(0.2, 1.0) / dt))
        tt = np.arange(min(n, t.size - k)) * dt
        out[k:k + tt.size] = rng.uniform(0.4, 1.0) * np.sin(2 * np.pi * f * tt)
        k += tt.size + rest
    return out


_BUILD = {"decay": _decay, "staircase": _staircase, "trapezoid": _trapezoid, "multisine": _multisine,
          "bursts": _bursts}


def excitation_alt(kind: str, t: np.ndarray, v_min: float, v_max: float, rng: np.random.Generator,
                   span_rng: np.random.Generator) -> np.ndarray:
    """Input voltage (V) of the given :data:`ALT_EXCITATIONS` kind over ``t`` within ``[v_min, v_max]``.

    The shape is built on −1..1 and mapped to ``centre ± half``: with probability ½ most of the range (centre 0.5,
    half-width 0.3–0.45 of it, so 0.6–0.9 of it wide), otherwise a part near one end or about the middle (centre
    0.2–0.8, half-width 0.08 up to 0.05 short of the nearer end), both drawn from ``span_rng``. The first 0.2 s
    ramp in from the middle of the range, as for the own excitations.
    """
    if kind not in _BUILD:
        raise ValueError(f"excitation kind must be one of {', '.join(ALT_EXCITATIONS)}, not {kind!r}")
    t = np.asarray(t, dtype=np.float64)
    if not (t.size >= 2 and t[-1] - t[0] >= 1.0):  # a multisine's lowest line and a staircase's holds need a second
        raise ValueError(f"an excitation needs at least 2 samples over at least 1 s, not {t.size} samples over "
                         f"{(t[-1] - t[0]) if t.size else 0.0:g} s")
    if span_rng.random() < 0.5:
        centre, half = 0.5, span_rng.uniform(0.3, 0.45)
    else:
        centre = span_rng.uniform(0.2, 0.8)
        half = span_rng.uniform(0.08, min(centre, 1.0 - centre) - 0.05)
    x = np.clip(centre + half * np.clip(_BUILD[kind](t, rng), -1.0, 1.0), 0.0, 1.0)
    ramp = np.clip(t / 0.2, 0.0, 1.0)
    x = 0.5 + ramp * (x - 0.5)
    return v_min + (v_max - v_min) * x
