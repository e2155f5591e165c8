"""Spectral lines in the output that the input does not drive: mains pickup, an amplifier's ripple, a fan.

A capacitive or inductive position sensor on a lab bench often picks up the mains (50 or 60 Hz and its odd
harmonics) or an amplifier's switching ripple. That is part of what no stage model can predict — sensor noise
that is not white — yet the noise floor of :func:`~hyst_model.effects.signals.noise_floor` (second differences)
barely sees it (a 50 Hz line at 2 kHz sampling keeps 0.2 % of its power in Δ²). Left out of the floor it makes a
stage whose model is complete look 2× off: generated stages with no effect and a 3σ-amplitude hum were answered
``unexplained`` (5 of 6) or ``dynamics`` (1 of 6).

:func:`disturbance_lines` finds such lines in a model's residual and returns them, so the floor can include
them (:func:`floor_with_lines`). A line counts only when all of these hold:

* **it is a line**: its periodogram bin (Hann window) exceeds the local spectral level (median of the
  neighbouring bins) by a factor a noise bin exceeds with probability ``FALSE_ALARM`` over the whole record
  (the bin ratio of Gaussian noise is exponential: ``κ = ln(bins / FALSE_ALARM)``);
* **the input does not drive it**: the input has no line at that frequency, and it is no sum or difference of
  multiples of the input's own lines (the harmonics and intermodulation a hysteresis makes of a sine or a
  periodic excitation);
* **it is stationary**: at least ten cycles in each quarter of the record, and fitted on each quarter separately,
  its amplitude and phase stay those of the whole record — a disturbance from outside is, a model error driven
  by an excitation that changes is not;
* **it matters**: its RMS is at least ``MIN_SHARE`` of the white-noise floor (smaller ones change the floor by
  little).

At most ``MAX_LINES`` are looked for (the strongest first); a list that long says so in words (:func:`said`: the
search stops there). A line's frequency, amplitude and phase are fitted on the whole record, held-out blocks
included: the periodogram and the quarters' stationarity test need it uniform and whole, and the three numbers
are the sensor's, not the stage's — taken out of every model's residual alike, they move no comparison between
models (what the held-out blocks are for).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import median_filter

__all__ = ["Line", "disturbance_lines", "floor_with_lines", "without_lines", "said", "removal_note", "FALSE_ALARM",
           "MIN_SHARE", "MAX_LINES"]

#: Chance that white or smoothly coloured noise alone shows a line anywhere in one record.
FALSE_ALARM = 1e-3
#: A line is kept when its RMS is at least this share of the white-noise floor.
MIN_SHARE = 0.5
#: At most this many lines: the mains, its odd harmonics and a rectifier's even ones (50–400 Hz) on a bench
#: sensor; each costs one more look at the spectrum (eight lines took 0.2 s on 60k samples, none 0.01 s).
MAX_LINES = 8
#: Half-width (bins) of the neighbourhood whose median is the local spectral level.
_LOCAL = 40
#: Half-width (bins) kept clear around a line: a Hann window spreads a line over about ±2 bins.
_CLEAR = 3
#: Multiples of the input's lines whose sums and differences are excluded (harmonics and intermodulation): a
#: dead zone driven by two sines left lines at order 40 (generated stage 9930020); fewer for more lines, so the
#: grid of combinations stays below _GRID.
_ORDER, _GRID = 60, 1_000_000
#: The orders up to which a weak input line (below _NARROW_INPUT) joins the products.
_WEAK_ORDER = 5
#: A line's bin is at least this many times the median of the bins 1–2 window widths beside it — in the residual;
#: an input line, whose products are left alone, the second: generated sines stood 10³–10⁸ above their side bins,
#: the fundamental of triangles whose amplitude changes by thirds 600–900, a low-passed noise input's bins about
#: 10 (generated stage 6500021: such "lines" and their products covered every frequency, and pickup was missed).
_NARROW, _NARROW_INPUT = 10.0, 100.0
#: Lowest bin looked at: ten cycles in each quarter of the record, so the quarters can test stationarity and a
#: slow trend (a drift's spectrum falls off from DC) is not taken for a line.
_MIN_BIN = 40
#: How far each quarter's amplitude (relative) and phase (rad) may stray from the whole record's.
_AMP_TOL, _PHASE_TOL = 0.35, 0.5


@dataclass(frozen=True)
class Line:
    """A sinusoid in the output at a frequency the input does not drive (SI: Hz, m)."""

    frequency: float     # Hz
    amplitude: float     # m, peak
    ratio: float         # its periodogram bin over the local spectral level
    phase: float = 0.0   # rad: the line is amplitude·cos(2π·frequency·t + phase) on the record's own time t

    @property
    def rms(self) -> float:
        """m (amplitude / √2)."""
        return self.amplitude / float(np.sqrt(2.0))

    def signal(self, t: np.ndarray) -> np.ndarray:
        """The line on the times ``t`` (s) of the record it was found in (m)."""
        return self.amplitude * np.cos(2.0 * np.pi * self.frequency * np.asarray(t, dtype=np.float64) + self.phase)

    def to_json(self) -> dict:
        return dict(asdict(self), rms=self.rms)


def _spectrum(x: np.ndarray) -> np.ndarray:
    w = np.hanning(x.size)
    return np.abs(np.fft.rfft((x - x.mean()) * w)) ** 2


def _level(p: np.ndarray) -> np.ndarray:
    """Local spectral level: the running median over ±_LOCAL bins, scaled to the mean of an exponential bin."""
    return median_filter(p, size=2 * _LOCAL + 1, mode="nearest") / np.log(2.0)


def _narrow(p: np.ndarray, k: int, factor: float = 0.0) -> bool:
    """A line, not a hump: bin ``k`` is ``_NARROW`` × the median of the bins 1–2 window widths beside it (a Hann
    line's side lobes there are 10⁻³ of it; noise at a steep edge of the spectrum, or a resonance, stays alike
    there; the median, so that a second line close by — two sines 1.25 Hz apart — does not count)."""
    side = np.r_[p[max(k - 3 * _CLEAR, 0):max(k - _CLEAR, 0)], p[k + _CLEAR + 1:k + 3 * _CLEAR + 1]]
    return bool(side.size) and bool(p[k] >= (factor or _NARROW) * np.median(side))


def _peaks(p: np.ndarray, kappa: float) -> np.ndarray:
    """Narrow bins that exceed ``kappa`` × the local level and are the largest within ±_CLEAR (DC left out)."""
    ratio = p / np.maximum(_level(p), 1e-300)
    ratio[:_MIN_BIN] = 0.0
    big = np.flatnonzero(ratio > kappa)
    return np.array([k for k in big if ratio[k] >= ratio[max(k - _CLEAR, 0):k + _CLEAR + 1].max()
                     and _narrow(p, int(k))], dtype=int)


def _driven(strong: np.ndarray, weak: np.ndarray, f_max: float) -> np.ndarray:
    """Frequencies (sorted) a nonlinearity makes of the input's lines: every Σ a_i·f_i up to ``f_max`` over the
    (at most 4) ``strong`` lines, a_i integers up to :data:`_ORDER` in size (fewer for more lines), with the (at
    most 2) ``weak`` ones joining at orders up to :data:`_WEAK_ORDER` — and every multiple of a strong line.

    A hysteresis driven by a few sines answers at their harmonics and intermodulation products of high order; by
    frequency alone a disturbance there cannot be told from a model error, so such frequencies are left alone
    (a sum of several sines covers most of the band: lines are then seldom found — the safe side). A weak line may
    be a sine of small amplitude (a Prandtl–Ishlinskii stage driven by three sines, one 26× its side bins, left
    its products in the residual) or a noise input's bump (a steps or noise input's bins reach 60×): only its low
    orders are left alone, which a bump's cannot cover the band with."""
    strong = np.asarray(strong, dtype=np.float64)[:4]
    weak = np.asarray(weak, dtype=np.float64)[:2]
    freqs = np.r_[strong, weak]
    if not freqs.size:
        return np.zeros(0)
    out = [f * np.arange(1, int(f_max / f) + 1) for f in strong]
    out += [f * np.arange(1, _WEAK_ORDER + 1) for f in weak]
    if freqs.size > 1:
        w = (2 * _WEAK_ORDER + 1) ** weak.size
        order = min(_ORDER, int(((_GRID / w) ** (1.0 / max(strong.size, 1)) - 1) // 2)) if strong.size else 0
        axes = [np.arange(-order, order + 1, dtype=np.float64)] * strong.size + \
            [np.arange(-_WEAK_ORDER, _WEAK_ORDER + 1, dtype=np.float64)] * weak.size
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, freqs.size)
        out.append(np.abs(grid @ freqs))
    d = np.concatenate(out)
    return np.sort(d[d <= f_max])


def _near(sorted_f: np.ndarray, f: float, tol: float) -> bool:
    i = int(np.searchsorted(sorted_f, f))
    return any(abs(sorted_f[j] - f) <= tol for j in (i - 1, i) if 0 <= j < sorted_f.size)


def _sinusoid(t: np.ndarray, x: np.ndarray, f: float) -> tuple[float, float]:
    """Least-squares amplitude and phase of a sinusoid at ``f`` (with an offset) in ``x``: the 3 × 3 normal
    equations of [cos, sin, 1] (a few dot products; it runs some thirty times per line)."""
    w = 2.0 * np.pi * f * t
    c, s = np.cos(w), np.sin(w)
    m = float(t.size)
    g = np.array([[c @ c, c @ s, c.sum()], [c @ s, s @ s, s.sum()], [c.sum(), s.sum(), m]])
    try:
        k = np.linalg.solve(g, np.array([c @ x, s @ x, x.sum()]))
    except np.linalg.LinAlgError:
        return 0.0, 0.0
    return float(np.hypot(k[0], k[1])), float(np.arctan2(-k[1], k[0]))


def _refine(t: np.ndarray, x: np.ndarray, f0: float, df: float) -> float:
    """The frequency near ``f0`` (within a bin) where the fitted sinusoid is largest (golden-section search)."""
    lo, hi = f0 - df, f0 + df
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = _sinusoid(t, x, a)[0], _sinusoid(t, x, b)[0]
    for _ in range(14):          # to 0.003 of a bin: the 100th harmonic of a line stays within a bin
        if fa > fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = _sinusoid(t, x, a)[0]
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = _sinusoid(t, x, b)[0]
    return 0.5 * (lo + hi)


def _stationary(t: np.ndarray, x: np.ndarray, f: float, amp: float, phase: float) -> bool:
    for q in np.array_split(np.arange(t.size), 4):
        a, ph = _sinusoid(t[q], x[q], f)
        if abs(a - amp) > _AMP_TOL * amp or abs(np.angle(np.exp(1j * (ph - phase)))) > _PHASE_TOL:
            return False
    return True


def disturbance_lines(t: np.ndarray, u: np.ndarray, e: np.ndarray, noise: float) -> list[Line]:
    """Lines in the residual ``e`` (m) the input ``u`` does not drive, strongest first (see the module).

    Parameters
    ----------
    t, u, e : ndarray
        Time (s; uniform but for jitter), input (V) and a model's residual (m) over the whole record.
    noise : float
        The white-noise floor (m): lines below ``MIN_SHARE`` of it are not reported.
    """
    t = np.asarray(t, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    x = np.asarray(e, dtype=np.float64).copy()
    n = x.size
    if n < 16 * (2 * _LOCAL + 1) or not noise > 0 or not np.all(np.isfinite(x)) or not t[-1] > t[0]:
        return []
    dt = float(np.median(np.diff(t)))
    df = 1.0 / (n * dt)
    bins = n // 2 + 1
    kappa = float(np.log(bins / FALSE_ALARM))
    pu = _spectrum(u)
    u_lines = np.flatnonzero(pu / np.maximum(_level(pu), 1e-300) > np.log(bins / 0.1))  # generous: exclude more
    u_lines = u_lines[u_lines > _CLEAR]
    # the input's strongest lines and what a nonlinearity makes of them
    # (their frequencies refined within the bin: the 50th harmonic of a bin's centre can be 25 bins off), and only
    # true lines (_NARROW_INPUT)
    top = [int(k) for k in u_lines[np.argsort(pu[u_lines])[::-1]]
           if pu[k] >= pu[max(k - _CLEAR, 0):k + _CLEAR + 1].max() and _narrow(pu, int(k))]
    # chosen first, refined then: a periodic input has hundreds of harmonics, each refinement some 16 fits
    strong = [_refine(t, u, k * df, df) for k in [k for k in top if _narrow(pu, k, _NARROW_INPUT)][:4]]
    weak = [_refine(t, u, k * df, df) for k in [k for k in top if not _narrow(pu, k, _NARROW_INPUT)][:2]]
    driven = _driven(np.array(strong), np.array(weak), 0.5 / dt)
    found: list[Line] = []
    refused: list[int] = []          # bins looked at and found not stationary
    for _ in range(3 * MAX_LINES):
        if len(found) == MAX_LINES:
            break
        p = _spectrum(x)
        level = np.maximum(_level(p), 1e-300)
        cands = [k for k in _peaks(p, kappa)
                 if not np.any(np.abs(u_lines - k) <= _CLEAR)
                 and not _near(driven, k * df, _CLEAR * df)
                 and not any(abs(k - r) <= _CLEAR for r in refused)]
        if not cands:
            break
        k = max(cands, key=lambda j: p[j])
        f = _refine(t, x, k * df, df)
        amp, phase = _sinusoid(t, x, f)
        if amp / np.sqrt(2.0) < MIN_SHARE * noise:
            break                    # the strongest left is too small to matter: so are the others
        if not _stationary(t, x, f, amp, phase):
            refused.append(k)
            continue
        found.append(Line(float(f), amp, float(p[k] / level[k]), phase))
        x = x - found[-1].signal(t)
    return found


def floor_with_lines(noise: float, lines: list[Line]) -> float:
    """The floor no model of the stage can go below: white noise and the lines together (RMS, m)."""
    return float(np.sqrt(noise ** 2 + sum(ln.rms ** 2 for ln in lines)))


def without_lines(t: np.ndarray, y: np.ndarray, lines: list[Line]) -> np.ndarray:
    """The record ``y`` (m) with the ``lines`` found in it taken out (a copy; ``y`` itself when there are none)."""
    if not lines:
        return y
    return np.asarray(y, dtype=np.float64) - sum(ln.signal(t) for ln in lines)


def said(lines: list[Line]) -> str:
    """The lines in words: "a line at 49.96 Hz (5.51 nm amplitude)" ("" for none)."""
    if not lines:
        return ""
    from ..effects.signals import fmt_len
    parts = ", ".join(f"{ln.frequency:.4g} Hz ({fmt_len(ln.amplitude)} amplitude)" for ln in lines)
    more = f" (the search stops at {MAX_LINES} lines)" if len(lines) >= MAX_LINES else ""
    return ("a line at " if len(lines) == 1 else "lines at ") + parts + more


def removal_note(lines: list[Line]) -> list[str]:
    """The data note ``hyst fit`` and ``hyst diagnose`` give for the lines they took out ([] for none)."""
    return [f"taken out of the output before fitting: {said(lines)}"] if lines else []
