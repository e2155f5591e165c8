"""Cases: a hysteresis truth, an excitation, hidden effects at a calibrated size, noise, and a fresh record."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter

from hyst_common.profiles import GMA, PEA, get_profile
from hyst_model.core import MBWParams, stage_model

from .excitation import EXCITATIONS, excitation
from .excitation_alt import ALT_EXCITATIONS, excitation_alt
from .forms import FORMS, LIBRARY_NAME, Ctx, draw
from .forms_alt import ALT_FORMS, ALT_LIBRARY_NAME, draw_alt

__all__ = ["Case", "generate_case", "case_family", "family_kinds", "KINDS", "EXPECTED", "SHAPES", "SENSORS",
           "EFFECT_FORMS", "FAMILY_WEIGHTS"]

#: Case kinds drawn by :func:`case_family`: one effect (large ≥ 5× noise, small 3–5×), a pair, an effect outside
#: the library, none, and a non-MBW (Prandtl–Ishlinskii) truth with no effect.
KINDS = ("single_large", "single_small", "pair", "outside", "none", "pi_truth")
#: Library effects a form is diagnosed as.
EXPECTED = sorted(set(LIBRARY_NAME.values()) - {"unexplained"})
RATE = 2000.0
DURATION = 8.0


@dataclass
class Case:
    """One generated stage record with its ground truth (arrays in SI: s, V, m)."""

    seed: int
    kind: str
    truth: str                    # "pea", "gma" (MBW) or "pi" (Prandtl–Ishlinskii)
    excitation: str
    forms: list                   # [(form name, strength in [0, 1])]
    expected: tuple               # library names, ("none",) or ("unexplained",) — PI truth: ("pi_truth",)
    size_over_noise: list         # achieved RMS change of each effect / noise σ
    noise: float
    t: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    t_fresh: np.ndarray = field(repr=False)
    u_fresh: np.ndarray = field(repr=False)
    y_fresh: np.ndarray = field(repr=False)

    @property
    def name(self) -> str:
        return f"{self.seed}:{self.kind}:{self.truth}:{self.excitation}:{'+'.join(f for f, _ in self.forms) or '-'}"


def _mbw_truth(profile: str, rng: np.random.Generator) -> MBWParams:
    p = stage_model(profile)
    return p.replace(zeta1=p.zeta1 * rng.uniform(0.85, 1.15), zeta2=p.zeta2 * rng.uniform(0.7, 1.3),
                     y_scale=p.y_scale * rng.uniform(0.8, 1.2),
                     offset=p.offset + rng.uniform(-2e-6, 2e-6))


#: Truth families: the thesis's identified shape with its scales varied, or shapes drawn wide (other actuators).
SHAPES = ("thesis", "wide")
#: Sensor noise: white (the benchmark's own), white with mains pickup (a 50 or 60 Hz line and its third harmonic),
#: white with band-limited noise (sensor electronics slower than the sampling), or a reading quantised in steps
#: coarser than its white noise (a digital sensor or a coarse ADC).
SENSORS = ("white", "hum", "coloured", "quantised")
#: The library effects' physical forms: the benchmark's own (:mod:`.forms`) or other laws (:mod:`.forms_alt`).
EFFECT_FORMS = ("own", "alt")
#: The excitations drawn: the benchmark's own (:mod:`.excitation`) or other schedules (:mod:`.excitation_alt`).
EXCITATION_SETS = ("own", "alt")
_ALL_FORMS = {**FORMS, **ALT_FORMS}
_NAME = {**LIBRARY_NAME, **ALT_LIBRARY_NAME}


def _sensor(kind: str, seed: int, t: np.ndarray, noise: float, record: int) -> np.ndarray:
    """What the sensor adds besides the white noise (m), drawn from its own stream (``seed``; the white families
    are unchanged): the same pickup or noise band on the fresh record (``record`` 1), with a new phase or
    realisation."""
    if kind == "white":
        return np.zeros(t.size)
    rng = np.random.default_rng([seed, 7919])                  # the sensor: one draw for both records
    phases = np.random.default_rng([seed, 7919, record])       # the record: its own phase / realisation
    if kind == "hum":
        f = float(rng.choice([50.0, 60.0])) * rng.uniform(0.998, 1.002)   # the grid's frequency tolerance
        a = rng.uniform(1.0, 4.0) * noise
        a3 = rng.uniform(0.1, 0.4) * a
        return (a * np.sin(2 * np.pi * f * t + phases.uniform(0, 2 * np.pi))
                + a3 * np.sin(6 * np.pi * f * t + phases.uniform(0, 2 * np.pi)))
    if kind == "coloured":
        rate = 1.0 / float(t[1] - t[0])
        fc = min(float(np.exp(rng.uniform(np.log(20.0), np.log(200.0)))), 0.25 * rate)
        level = rng.uniform(1.0, 3.0) * noise
        c = np.exp(-2 * np.pi * fc / rate)                       # first-order low-pass, unit variance
        x = lfilter([np.sqrt(1 - c * c)], [1.0, -c], phases.standard_normal(t.size))
        return level * x
    raise ValueError(f"sensor must be one of {', '.join(SENSORS)}, not {kind!r}")


def _read(kind: str, seed: int, t: np.ndarray, clean: np.ndarray, white: np.ndarray, noise: float,
          record: int) -> np.ndarray:
    """The sensor's reading (m) of the stage's output ``clean`` with the standard-normal draw ``white``.

    ``"quantised"``: the reading is rounded to a lattice of step q (its zero at a random offset) after white noise
    σ' was added; q/σ' is drawn log-uniform in 2–10 (per sensor) and σ'² + q²/12 = ``noise``², so the reading's
    error has the same RMS as the white families' and the effect sizes mean the same. Every other kind adds
    ``noise`` × ``white`` and :func:`_sensor`'s part, as before (bit for bit)."""
    if kind != "quantised":
        return clean + noise * white + _sensor(kind, seed, t, noise, record)
    rng = np.random.default_rng([seed, 7919])                  # the sensor: one draw for both records
    ratio = float(np.exp(rng.uniform(np.log(2.0), np.log(10.0))))
    sigma = noise / np.sqrt(1.0 + ratio * ratio / 12.0)
    q = ratio * sigma
    zero = rng.uniform(0.0, q)
    return zero + q * np.round((clean + sigma * white - zero) / q)


def _wide_truth(profile: str, rng: np.random.Generator) -> MBWParams:
    """An MBW stage of another shape than the thesis's: ζ, ψ, α and the memories δ1, δ2 drawn over wide ranges
    (Remark 4.1 kept: α < −|ψ|), the loop 3–25 % of the stroke wide, scaled to 0.8–1.2 × the profile's stroke."""
    p0 = stage_model(profile)
    prof = get_profile(profile)
    t = np.arange(4000) / 2000.0
    u = prof.v_min + (prof.v_max - prof.v_min) * (0.5 + 0.5 * np.sin(2 * np.pi * t))
    for _ in range(200):
        psi1 = rng.uniform(0.005, 0.12)
        psi2 = rng.uniform(-0.05, 0.05)
        p = p0.replace(zeta1=rng.uniform(0.2, 0.7), zeta2=rng.uniform(0.0, 0.05), psi1=psi1, psi2=psi2,
                       alpha1=-abs(psi1) * rng.uniform(1.1, 3.0), alpha2=-abs(psi2) * rng.uniform(1.1, 3.0) - 0.005,
                       delta1=rng.uniform(0.9, 0.99), delta2=rng.uniform(0.9, 0.99))
        y = p.simulate(u)[2000:]
        if not np.all(np.isfinite(y)) or np.ptp(y) <= 0:
            continue
        uu = u[2000:]
        up = np.diff(uu, prepend=uu[0]) > 0
        grid = np.linspace(uu.min() + 0.1 * np.ptp(uu), uu.max() - 0.1 * np.ptp(uu), 20)
        ya = np.interp(grid, np.sort(uu[up]), y[up][np.argsort(uu[up])])
        yd = np.interp(grid, np.sort(uu[~up]), y[~up][np.argsort(uu[~up])])
        width = np.max(np.abs(ya - yd)) / np.ptp(y)
        if not 0.03 <= width <= 0.25:
            continue
        scale = prof.stroke * rng.uniform(0.8, 1.2) / np.ptp(y)
        return p.replace(y_scale=p.y_scale * scale, offset=p.offset + rng.uniform(-2e-6, 2e-6))
    raise RuntimeError("no MBW shape with a 3-25 % loop drawn in 200 tries")


def _pi_simulator(v_min: float, v_max: float, stroke: float, rng: np.random.Generator):
    """Prandtl–Ishlinskii: linear term plus play operators with random, decreasing weights."""
    n = 8
    r = np.linspace(0.0, 0.45, n) * (v_max - v_min)
    w = np.sort(rng.uniform(0.2, 1.0, n))[::-1] * rng.uniform(0.3, 1.0)
    w[0] = 1.0

    def sim(u: np.ndarray) -> np.ndarray:
        s = np.full(n, u[0])
        out = np.empty(u.size)
        for k, v in enumerate(u):
            s = np.minimum(np.maximum(s, v - r), v + r)
            out[k] = w @ s
        lo, hi = w.sum() * v_min, w.sum() * v_max
        return (out - lo) / (hi - lo) * stroke
    return sim


def _apply(forms, ctx: Ctx, draws: dict[str, dict]):
    u, y = ctx.u, ctx.x
    for name, amp in forms:
        c = Ctx(ctx.t, u, ctx.simulate, y, ctx.span, draws[name])
        u, y = _ALL_FORMS[name][0](c, amp)
    return u, y


def _calibrate(name: str, ctx: Ctx, draws: dict[str, dict], target: float) -> tuple[float, float]:
    """Strength in (0, 1] whose RMS output change is ``target`` (m), by bisection; the size reached.

    ``draws`` holds each form's private rng draw (by form name)."""
    c = Ctx(ctx.t, ctx.u, ctx.simulate, ctx.x, ctx.span, draws[name])

    def size(a: float) -> float:
        return float(np.sqrt(np.mean((_ALL_FORMS[name][0](c, a)[1] - ctx.x) ** 2)))
    lo, hi = 0.0, 1.0
    if size(hi) <= target:
        return hi, size(hi)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if size(mid) < target else (lo, mid)
    return hi, size(hi)


def generate_case(seed: int, kind: str | None = None, *, rate: float = RATE, duration: float = DURATION,
                  shapes: str = "thesis", sensor: str = "white", effect_forms: str = "own",
                  excitations: str = "own") -> Case:
    """One case, fully determined by ``seed`` (and ``kind``; drawn from :data:`KINDS` if omitted).

    ``rate`` (Hz) and ``duration`` (s) set the record's sampling; the defaults are the benchmark's own family, and
    other values give families the diagnosis was not developed on (a mode's frequency stays below 0.35 × rate).
    ``shapes``: the MBW truths' family (:data:`SHAPES`): ``"thesis"`` (the benchmark's own) or ``"wide"``.
    ``sensor`` (:data:`SENSORS`): what the sensor adds to the white noise — nothing (the benchmark's own), mains
    pickup, band-limited noise or a coarse quantiser; the rest of the case is the same as with white noise.
    ``effect_forms`` (:data:`EFFECT_FORMS`): the library effects' physical forms — the benchmark's own
    (:mod:`.forms`) or other laws of the same physics (:mod:`.forms_alt`); effects outside the library and the
    cases without an effect are drawn alike.
    ``excitations`` (:data:`EXCITATION_SETS`): the excitations — the benchmark's own, or other identification
    schedules (:mod:`.excitation_alt`: decaying sines, staircases, trapezoids, multisines, bursts, over all or
    part of the range); a fresh record is always a new realisation over the same part of the range.
    """
    if excitations not in EXCITATION_SETS:
        raise ValueError(f"excitations must be one of {', '.join(EXCITATION_SETS)}, not {excitations!r}")
    if effect_forms not in EFFECT_FORMS:
        raise ValueError(f"effect_forms must be one of {', '.join(EFFECT_FORMS)}, not {effect_forms!r}")
    if shapes not in SHAPES:
        raise ValueError(f"shapes must be one of {', '.join(SHAPES)}, not {shapes!r}")
    if sensor not in SENSORS:
        raise ValueError(f"sensor must be one of {', '.join(SENSORS)}, not {sensor!r}")
    if not (rate > 0 and duration > 0 and rate * duration >= 1000):
        raise ValueError(f"a case needs a positive rate and duration and at least 1000 samples "
                         f"(rate {rate} Hz, duration {duration} s)")
    rng = np.random.default_rng(seed)
    kind = kind or str(rng.choice(KINDS))
    truth = "pi" if kind == "pi_truth" else str(rng.choice(["pea", "gma"]))
    prof = GMA if truth == "gma" else (PEA if truth == "pea" else (PEA if rng.random() < 0.5 else GMA))
    exc = str(rng.choice(EXCITATIONS if excitations == "own" else ALT_EXCITATIONS))
    t = np.arange(int(round(duration * rate))) / rate
    if truth == "pi":
        simulate = _pi_simulator(prof.v_min, prof.v_max, prof.stroke, rng)
    else:
        p = _mbw_truth(truth, rng) if shapes == "thesis" else _wide_truth(truth, rng)
        simulate = p.simulate
    noise = float(rng.uniform(1e-9, 4e-9))
    lib = [f for f, n in (ALT_LIBRARY_NAME if effect_forms == "alt" else LIBRARY_NAME).items() if n != "unexplained"]
    out = [f for f, n in LIBRARY_NAME.items() if n == "unexplained"]
    if kind in ("single_large", "single_small"):
        forms = [str(rng.choice(lib))]
    elif kind == "pair":
        a = str(rng.choice(lib))
        forms = [a, str(rng.choice([f for f in lib if _NAME[f] != _NAME[a]]))]
    elif kind == "outside":
        forms = [str(rng.choice(out))]
    else:
        forms = []
    draws = {f: draw_alt(rng, rate) if f in ALT_FORMS else draw(f, rng, duration, rate) for f in forms}
    lo_hi = (3.0, 5.0) if kind == "single_small" else (5.0, 200.0)
    targets = [float(np.exp(rng.uniform(*np.log(lo_hi)))) * noise for _ in forms]
    seeds = rng.integers(0, 2**31, 3)

    def record(u_seed: int, noise_seed: int):
        r2 = np.random.default_rng(u_seed)
        if excitations == "own":
            u = excitation(exc, t, prof.v_min, prof.v_max, r2)
        else:  # the part of the range from the case's first seed: a fresh record covers the same part
            u = excitation_alt(exc, t, prof.v_min, prof.v_max, r2, np.random.default_rng([int(seeds[0]), 1]))
        x = simulate(u)
        ctx = Ctx(t, u, simulate, x, prof.stroke, {})
        return u, x, ctx, np.random.default_rng(noise_seed)

    u, x, ctx, nrng = record(int(seeds[0]), int(seeds[1]))
    strengths: list[tuple[str, float]] = []
    sizes: list[float] = []
    for f, tg in zip(forms, targets):
        amp, s = _calibrate(f, ctx, draws, tg)
        strengths.append((f, amp))
        sizes.append(s / noise)
    ua, y = _apply(strengths, ctx, draws)
    y = _read(sensor, seed, t, y, nrng.standard_normal(t.size), noise, 0)
    # fresh record of the same stage: new noise; random excitations get a new realisation too
    fresh_u_seed = int(seeds[0]) if excitations == "own" and exc in ("triangles", "sweep") else int(seeds[2])
    uf, xf, ctxf, nrng_f = record(fresh_u_seed, int(seeds[2]) + 1)
    _, yf = _apply(strengths, ctxf, draws)
    yf = _read(sensor, seed, t, yf, nrng_f.standard_normal(t.size), noise, 1)
    expected: tuple[str, ...]
    if kind == "pi_truth":
        expected = ("pi_truth",)
    elif not forms:
        expected = ("none",)
    else:
        expected = tuple(_NAME[f] for f in forms)
    return Case(seed, kind, truth, exc, strengths, expected, sizes, noise, t, u, y, t.copy(), uf, yf)


def case_family(n: int, seed: int = 0, *, rate: float = RATE, duration: float = DURATION,
                shapes: str = "thesis", sensor: str = "white", effect_forms: str = "own",
                excitations: str = "own") -> list[Case]:
    """``n`` cases with a balanced mix of :data:`KINDS` (singles weighted up), seeds ``seed*100000 + i``."""
    return [generate_case(seed * 100000 + i, k, rate=rate, duration=duration, shapes=shapes, sensor=sensor,
                          effect_forms=effect_forms, excitations=excitations) for i, k in enumerate(family_kinds(n))]


#: How often each kind comes in a family (singles weighted up), in the order they cycle.
FAMILY_WEIGHTS = {"single_large": 4, "single_small": 2, "pair": 2, "outside": 1, "none": 2, "pi_truth": 1}


def family_kinds(n: int) -> list[str]:
    """The kinds of a family's first ``n`` cases (case i has seed ``seed*100000 + i``)."""
    order = [k for k, w in FAMILY_WEIGHTS.items() for _ in range(w)]
    return [order[i % len(order)] for i in range(n)]
