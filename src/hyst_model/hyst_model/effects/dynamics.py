"""Dynamics: linear second-order (mass-spring-damper) dynamics around the hysteresis, in the two structures a lab
meets.

``series`` (config ``dynamics.structure: series``, the default) — hysteresis followed by the stage's resonance:
the inner model's output ``x`` drives a unit-DC-gain second-order low-pass

    ÿ_m + 2ζω_n ẏ_m + ω_n² y_m = ω_n² x,     ω_n = 2π·fn,      y = (1 − part)·x + part·y_m,

where ``part`` is the mode's participation at the sensor (modal superposition: the share of the static
displacement that passes through this mode; the rest reaches the sensor without it, as when the sensor sits
between a stiff and a compliant part of the flexure). ``part = 1`` (the default, and what a params file written
before the parameter existed means) is the whole motion through the mode. With ``part < 1`` the reading has a
lightly damped anti-resonance above the resonance (zeros at ω_n/√(1 − part)), minimum phase, so the
controllers' inverse stays stable. The damping ratio is bounded by 1 — a resonance, not an overdamped lag: two
real poles with a partial participation are two first-order lags with a static share, which is what creep looks
like (that is ``creep``'s job; with ζ allowed up to 3 the mode took 6 of 13 generated creep records); for
the same reason its resonance lies above creep's time scales (:data:`SERIES_FN_MIN`, 15.9 Hz).

The mode is discretised exactly, starting at rest at ``x[0]``, for one of two inputs between samples
(``dynamics.hold``):

* ``zoh`` (default) — the input is held over each sample period, as a DAC-driven amplifier holds the voltage:
  ``s_k = Φ s_{k−1} + Γ x_k``; sample ``k`` reads the stage at the end of the period over which ``x_k`` was held,
  the MBW's own timing (``y_k`` responds to ``u_k``; a further transport delay is the ``delay`` effect's job).
  Where the sensor samples within the hold is the parameter ``lag`` (0…1 sample): 0 is that timing, 1 the
  textbook ZOH in which ``x_{k−1}`` is held over the period before sample ``k`` (strictly proper, as
  ``scipy.signal.cont2discrete`` gives it). The two differ by one sample at the resonance — 54° of phase for
  300 Hz at 2 kHz — so a mode read with the other timing was fitted as a delay; a rig's ADC/DAC timing lies
  anywhere between (:func:`~.dynamics_kernels.zoh_matrices`);
* ``foh`` — the input is linear between samples (first-order hold), right for smooth, band-limited inputs.

With ``dynamics.modes: 2`` a second mode (``fn2``, ``zeta2``) is driven by the first's displacement — the flexure
and, say, the sensor mount both resonate — and ``part`` is the share through both. The cascade is discretised as
one four-state system with one hold and one ``lag`` (a stage between one DAC and one ADC has one hold however many
modes it has; discretising each mode on its own would put one more sample of delay between them).

On the simulated PEA stage with a hidden 350 Hz resonance (ζ = 0.04) the two differ by 0.9 µm RMS: a lightly
damped resonance near Nyquist is sensitive to what the input does between samples. With ``fn`` near Nyquist and
ζ ≈ 0.7 either is almost the identity. This is a piezo stage whose flexure resonance (hundreds of Hz to kHz) is
excited by fast commands: the loop tilts with frequency, step responses ring.

``feedback`` (config ``dynamics.structure: feedback``) — a hysteretic restoring force inside a mass-spring-damper,
as in the Bouc-Wen benchmark (Noël & Schoukens 2016, ../shared/data/boucwen_benchmark):

    m ÿ + c ẏ + k y + z = u,     ż = α ẏ − β(γ |ẏ| z + δ ẏ |z|)      (Bouc-Wen, ν = 1)

Divided by the small-signal stiffness k + α (the tangent stiffness at z = 0) it is written with
SI parameters that are each meaningful on their own:

    fn    = sqrt((k+α)/m) / 2π           small-signal natural frequency (Hz)
    zeta  = c / (2 sqrt((k+α) m))        damping ratio
    gain  = 1 / (k+α)                    small-signal compliance (m per input unit)
    share = α / (k+α)                    hysteretic part of the stiffness (0 = linear spring)
    bg, bd = β γ, β δ                    Bouc-Wen loop shape (1/m)

so that with ``w = z/(k+α)`` (m)

    ÿ = ω_n² (gain·u − (1 − share)·y − w) − 2ζω_n ẏ,     ẇ = share·ẏ − bg |ẏ| w − bd ẏ |w|.

The benchmark's values are fn = 35.59 Hz, ζ = 1.12 %, gain = 1e-5 m/N, share = 0.5, bg = 800 /m, bd = −1100 /m.
The state is integrated with classical RK4 at ``dynamics.substeps`` (default 10) steps per sample, numba-compiled:
against 40 substeps the displacement differs by 1e-4 of its RMS with fn at 0.49·fs and by 1e-6 at fn = 0.1·fs
(measured on a random-walk input; RK4's error falls as substeps⁻⁴). ``tools/boucwen_benchmark.py`` uses 20
(the benchmark's guideline: 15 kHz for 750 Hz data). The input between samples is interpolated linearly
(``dynamics.interp: linear``) or band-limited (``fft``: exact for periodic records such as multisines). In this
structure the effect *replaces* the base model (kind ``base``): the restoring force carries the hysteresis, and
only the base's fitted ``offset`` (if it has one) is kept.

The numerical kernels are in :mod:`.dynamics_kernels`, the residual evidence in :mod:`.dynamics_evidence`.

Which structure fits a given actuator is an empirical question: :func:`choose_structure` fits both and keeps
the one with the lower validation RMSE; :meth:`DynamicsEffect.variants` offers both to ``hyst diagnose``, which
does the same.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import EffectError
from ..model import Param
from .base import Effect
from .dynamics_evidence import coherence_test, residual_peak
from .dynamics_kernels import HOLDS, msd_bw_simulate, series_filter, upsample
from .dynamics_online import SeriesResonanceInverse
from .signals import corr, holds, sample_time, smooth

__all__ = ["DynamicsEffect", "series_filter", "msd_bw_simulate", "upsample", "choose_structure",
           "StructureChoice", "SeriesResonanceInverse", "BENCHMARK_TRUTH", "STRUCTURES", "HOLDS"]

STRUCTURES = ("series", "feedback")

#: Lowest resonance of the series structure (Hz): the fastest creep lag's corner, 1/(2π·10 ms). Slower, a mode
#: with a partial participation is a lag with a static share — creep's time scales, which ``creep`` models; with
#: the old 0.2 Hz floor a 2-4 Hz mode with 1-3 % participation took creep records whose input had no holds.
SERIES_FN_MIN = float(1.0 / (2.0 * np.pi * 0.01))

#: The Bouc-Wen benchmark system (Noël & Schoukens 2016, Table 1) in this effect's ``feedback`` parameters.
BENCHMARK_TRUTH: dict[str, float] = {
    "fn": float(np.sqrt(1e5 / 2.0) / (2 * np.pi)),  # 35.59 Hz
    "zeta": float(10.0 / (2.0 * np.sqrt(1e5 * 2.0))),  # 1.118 %
    "gain": 1e-5,  # m/N
    "share": 0.5,
    "bg": 1e3 * 0.8,
    "bd": 1e3 * -1.1,
}


# ----------------------------------------------------------------------------------------------- the effect
#: A mode read within this many samples of a whole sample into the hold is inverted as the lag-0 mode read one
#: sample later (:meth:`DynamicsEffect.online`).
LAG_SNAP = 0.1


class DynamicsEffect(Effect):
    """Linear second-order dynamics: resonance after the hysteresis (``series``) or a hysteretic restoring force
    in a mass-spring-damper (``feedback``); the structure is fixed configuration ``dynamics.structure``."""

    name = "dynamics"
    summary = "stage resonance / inertia: second-order dynamics after or around the hysteresis"
    physics = ("The stage has mass and a flexure spring: fast inputs excite its resonance, so the output lags, "
               "overshoots and rings after steps, and the loop tilts and grows with frequency. Either the "
               "hysteresis drives the resonant stage (series), or the hysteresis is part of the spring force of "
               "a mass-spring-damper (feedback, as in the Bouc-Wen benchmark).")
    kind = "wrap"
    online_note = ("only the series structure with a held input (dynamics.hold: zoh) has a per-sample inverse; this "
                   "one acts on the loop as unmodelled dynamics (the controller checks its gains against it)")

    def __init__(self, config: Mapping[str, object] | None = None):
        super().__init__(config)
        cfg = self._config
        self.structure = str(cfg.get("dynamics.structure", "series"))
        if self.structure not in STRUCTURES:
            raise EffectError(f"dynamics.structure must be one of {', '.join(STRUCTURES)}, not {self.structure!r}")
        sub = float(cfg.get("dynamics.substeps", 10))
        if not (np.isfinite(sub) and sub == int(sub) and 1 <= sub <= 1000):  # 2.5 ran (and was saved) as 2
            raise EffectError(f"dynamics.substeps must be a whole number between 1 and 1000, not {sub:g}")
        self.substeps = int(sub)
        self.hold = str(cfg.get("dynamics.hold", "zoh"))
        if self.hold not in HOLDS:
            raise EffectError(f"dynamics.hold must be one of {', '.join(HOLDS)}, not {self.hold!r}")
        modes = float(cfg.get("dynamics.modes", 1))
        self.modes = int(modes) if modes in (1.0, 2.0) else 0
        if self.modes not in (1, 2):
            raise EffectError(f"dynamics.modes must be 1 or 2, not {cfg.get('dynamics.modes')!r}")
        if self.modes == 2 and self.structure != "series":
            raise EffectError("dynamics.modes: 2 (a second mode in cascade) exists only in the series structure")
        self.interp = str(cfg.get("dynamics.interp", "linear"))
        if self.interp not in ("linear", "fft"):
            raise EffectError(f"dynamics.interp must be 'linear' or 'fft', not {self.interp!r}")
        # The feedback structure replaces the base model and keeps only its offset; the instance attributes
        # tell ComposedModel (and the fitters) so.
        self.kind = "base" if self.structure == "feedback" else "wrap"
        self.base_params_used = ("offset",) if self.structure == "feedback" else None
        self.linear = self.structure == "series"  # a linear filter after the hysteresis
        self.on_base = True  # the series inverse drives its state with the base model's prediction
        self._ufine_cache: tuple | None = None

    def config(self) -> dict[str, float | str]:
        return {"structure": self.structure, "hold": self.hold, "substeps": float(self.substeps),
                "interp": self.interp, "modes": float(self.modes)}

    @property
    def _lagged(self) -> bool:
        """The series structure with a held input has the sampling-lag parameter."""
        return self.structure == "series" and self.hold == "zoh"

    def legacy_values(self) -> dict[str, float]:
        # params files from before the participation / the sampling lag existed: the whole motion passes the
        # mode, read at the end of the hold
        if self.structure != "series":
            return {}
        return {"part": 1.0, "lag": 0.0} if self._lagged else {"part": 1.0}

    @staticmethod
    def variants() -> list[dict[str, object]]:
        """Configurations ``hyst diagnose`` tries, keeping whichever validates better: both structures, and the
        series structure with two modes in cascade (a stage whose flexure and sensor mount both resonate: one
        mode fitted to two left 6x the noise floor where a delay imitated their joint phase lag better)."""
        return [{"dynamics.structure": "series", "dynamics.modes": 1.0},
                {"dynamics.structure": "feedback", "dynamics.modes": 1.0},
                {"dynamics.structure": "series", "dynamics.modes": 2.0}]

    def params(self) -> tuple[Param, ...]:
        fs = 1.0 / self.dt
        nyq = 0.49 * fs
        if self.structure == "series":
            return (Param("fn", 0.4 * fs, SERIES_FN_MIN, nyq, "Hz",
                          "natural frequency of the stage after the hysteresis"),
                    Param("zeta", 0.7, 1e-3, 1.0, "", "damping ratio of that resonance (≤ 1: a resonance)"),
                    Param("part", 1.0, 0.0, 1.0, "", "participation: share of the displacement through the mode"),
                    ) + ((Param("lag", 0.0, 0.0, 1.0, "sample", "where the sensor samples within the input's hold "
                                "(0: at its end, the MBW's timing; 1: one period later, the textbook ZOH)"),)
                         if self._lagged else ()) + self._second_params(fs)
        gref = self.y_scale / self.u_scale
        yref = 10.0 * self.y_scale
        return (Param("fn", 0.05 * fs, 0.2, nyq, "Hz", "small-signal natural frequency sqrt((k+α)/m)/2π"),
                Param("zeta", 0.05, 1e-4, 3.0, "", "damping ratio c/(2 sqrt((k+α) m))"),
                Param("gain", 0.4 * gref, 1e-4 * gref, 1e3 * gref, "m/unit", "small-signal compliance 1/(k+α)"),
                Param("share", 0.5, 0.0, 0.999, "", "hysteretic share α/(k+α) of the stiffness"),
                Param("bg", 0.0, -200.0 / yref, 200.0 / yref, "1/m", "Bouc-Wen β·γ (loop shape)"),
                Param("bd", 0.0, -200.0 / yref, 200.0 / yref, "1/m", "Bouc-Wen β·δ (loop shape)"))

    def _second_params(self, fs: float) -> tuple[Param, ...]:
        """The second mode's parameters (``dynamics.modes: 2``), last in θ; none for one mode."""
        if self.modes == 1:
            return ()
        return (Param("fn2", 0.45 * fs, SERIES_FN_MIN, 0.49 * fs, "Hz",
                      "natural frequency of the second mode, in cascade after the first"),
                Param("zeta2", 0.7, 1e-3, 1.0, "", "damping ratio of the second mode"))

    def check(self, base, others) -> None:
        super().check(base, others)
        if self.structure == "feedback" and any(getattr(o, "kind", "") == "base" for o in others):
            raise EffectError("dynamics (feedback structure) replaces the base model and cannot be combined with "
                              "another effect that does the same (e.g. rate)")

    # simulation -----------------------------------------------------------------------------------------
    def _fine(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        key = (u.size, float(u[0]), float(u[-1]), float(np.sum(u)), float(np.sum(u * u)), self.substeps,
               self.interp)
        if self._ufine_cache is None or self._ufine_cache[0] != key:
            self._ufine_cache = (key, upsample(u, 2 * self.substeps, self.interp))
        return self._ufine_cache[1]

    def simulate_feedback(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray,
                          state0: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Displacement of the feedback structure from state ``(y, ẏ, w)`` (default: at rest, zero force)."""
        t = np.asarray(t, dtype=np.float64)
        u = np.ascontiguousarray(u, dtype=np.float64)
        dt = sample_time(t) if t.size > 1 else self.dt
        p = np.ascontiguousarray(theta, dtype=np.float64)
        return msd_bw_simulate(p, self._fine(t, u), self.substeps, dt, *map(float, state0))

    @property
    def acts_on_output(self) -> bool:
        """The series structure is an output effect in all but name (:meth:`output` on the inner output): a
        linear operator (:attr:`linear`) the fitters carry the base's sensitivities through, column by column."""
        return self.structure == "series"

    def output(self, theta, t, u, y):
        """Series structure: the mode acting on the inner output ``y`` (at rest at y[0])."""
        t = np.asarray(t, dtype=np.float64)
        x = np.asarray(y, dtype=np.float64)
        dt = sample_time(t) if t.size > 1 else self.dt
        lag = float(theta[3]) if self._lagged else 0.0
        k = 4 if self._lagged else 3  # the second mode's fn2, zeta2 follow lag
        ym = series_filter(x, float(theta[0]), float(theta[1]), dt, self.hold, lag,
                           (float(theta[k]), float(theta[k + 1])) if self.modes == 2 else None)
        part = float(theta[2])
        return ym if part == 1.0 else x + part * (ym - x)

    def apply(self, theta, t, u, inner):
        t = np.asarray(t, dtype=np.float64)
        if self.structure == "series":
            return self.output(theta, t, u, inner(t, u))
        offset = 0.0
        try:
            offset = float(inner.model.unpack(inner.theta).get("offset", 0.0))
        except Exception:  # noqa: BLE001 - a base without named parameters simply has no offset
            offset = 0.0
        u = np.asarray(u, dtype=np.float64)
        if u.size and u[0] != 0.0:
            # Start at rest under the initial input: the static equilibrium after a slow virgin loading is
            # approximated by the linear equilibrium y = gain·u0 (w = share·y on the virgin curve with bg=bd=0).
            y0 = float(theta[2]) * float(u[0])
            return self.simulate_feedback(theta, t, u, (y0, 0.0, float(theta[3]) * y0)) + offset
        return self.simulate_feedback(theta, t, u) + offset

    def online(self, theta, base=None):
        """The series resonance's per-sample inverse, or None — with the reason in :attr:`online_note` — where
        there is none: another structure or hold, or a mode read so late in the hold that its sampled zero leaves
        the unit circle (a diagnosis can name such a mode: refusing the whole model for it left the controllers
        nothing; the gains are still checked against the mode, :mod:`hyst_control.stability`)."""
        if self.structure != "series" or self.hold != "zoh" or base is None:
            return None
        fn, zeta, part, lag = (float(v) for v in theta[:4])
        second = (float(theta[4]), float(theta[5])) if self.modes == 2 else None
        try:
            return SeriesResonanceInverse(fn, zeta, self.dt, base, part, lag, second=second)
        except ValueError as err:
            # Read a whole sample into the hold, the mode is the lag-0 mode read one sample later (exactly, at
            # lag 1): inverted as such, with the reference previewed. Within LAG_SNAP of it the rounding is the
            # only error (0.1 sample: 14 degrees at 400 Hz, 2 kHz); further away there is no inverse.
            if abs(lag - 1.0) <= LAG_SNAP:
                try:
                    return SeriesResonanceInverse(fn, zeta, self.dt, base, part, 0.0, delay=1, second=second)
                except ValueError:
                    pass
            self.online_note = f"{err}; not inverted (the gains are still checked against it)"
            return None

    # identification helpers -----------------------------------------------------------------------------
    def start(self, t, u, y, residual):
        t = np.asarray(t, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        dt = sample_time(t)
        fs = 1.0 / dt
        lo = SERIES_FN_MIN if self.structure == "series" else max(0.5, 2.0 / (t[-1] - t[0] + dt))
        grid = np.geomspace(lo, 0.45 * fs, 24)
        peak = residual_peak(np.asarray(u, dtype=np.float64), np.asarray(residual, dtype=np.float64), dt)
        if peak is not None and peak >= lo:  # the resonance the residual shows, so a lightly damped one is not missed
            grid = np.sort(np.r_[grid, peak])
        zetas = (0.01, 0.05, 0.2, 0.7)
        if self.structure == "series":
            x = y - np.asarray(residual, dtype=np.float64)  # the inner model's output
            best = (np.inf, None)
            ex = y - x
            for lag in ((0.0, 0.5, 1.0) if self._lagged else (0.0,)):
                for fn in grid:
                    for z in zetas:
                        # what the whole mode adds, its participation by least squares
                        c, part = _participation(series_filter(x, fn, z, dt, self.hold, lag) - x, ex)
                        if c < best[0]:
                            best = (c, {"fn": float(fn), "zeta": float(z), "part": part}
                                    | ({"lag": lag} if self._lagged else {}))
            if self.modes == 2 and best[1] is not None:
                best = self._second_start(x, ex, dt, grid, zetas, best)
            return best[1] or {}
        # feedback: the linear MSD (bg = bd = 0) with the compliance fitted by least squares, per (fn, ζ).
        u = np.asarray(u, dtype=np.float64)
        yc = y - np.mean(y)
        best = (np.inf, None)
        for fn in grid[::2]:
            for z in zetas:
                s = series_filter(u, fn, z, dt)  # unit-gain response of the linear MSD
                sc = s - s.mean()
                den = float(sc @ sc)
                if den <= 0:
                    continue
                g = float(sc @ yc) / den
                r = yc - g * sc
                c = float(r @ r)
                if c < best[0]:
                    best = (c, {"fn": float(fn), "zeta": float(z), "gain": g, "share": 0.5, "bg": 0.0, "bd": 0.0})
        return best[1] or {}

    def _second_start(self, x: np.ndarray, ex: np.ndarray, dt: float, grid: np.ndarray, zetas: tuple,
                      best: tuple) -> tuple:
        """The second mode's start: the first held at its best single-mode start, the second scanned on the same
        grid (participation by least squares again); near the identity (fast, damped) when none helps."""
        v = best[1]
        out = (np.inf, {**v, "fn2": float(grid[-1]), "zeta2": 0.7})
        for fn in grid:
            for z in zetas:
                c, part = _participation(
                    series_filter(x, v["fn"], v["zeta"], dt, self.hold, v.get("lag", 0.0), (fn, z)) - x, ex)
                if c < out[0]:
                    out = (c, {**v, "part": part, "fn2": float(fn), "zeta2": float(z)})
        return out

    def signature(self, t, u, residual, dt):
        """Dynamics leaves a residual that follows the input's acceleration, beyond its velocity, or rings after
        steps. Score: the share of residual variance the acceleration explains on top of the velocity, or the
        oscillation of the residual after steps."""
        u = np.asarray(u, dtype=np.float64)
        r = np.asarray(residual, dtype=np.float64)
        if u.size < 50:
            return 0.0, "record too short to test for dynamics"
        n_s = max(1, int(round(3 * dt / dt)))
        us = smooth(u, n_s)
        ud = np.gradient(us, dt)
        udd = np.gradient(ud, dt)
        rc = r - r.mean()
        var = float(rc @ rc)
        if var <= 0:
            return 0.0, "no residual left"

        def r2(cols):
            X = np.column_stack([np.ones_like(rc)] + cols)
            coef, *_ = np.linalg.lstsq(X, rc, rcond=None)
            e = rc - X @ coef
            return 1.0 - float(e @ e) / var

        r2v = r2([ud])
        r2va = r2([ud, udd])
        gain = max(r2va - r2v, 0.0)
        ring_score, ring_txt = 0.0, ""
        for a, b, step in holds(u, dt, min_seconds=20 * dt, rel_tol=2e-3)[:20]:
            if step == 0.0 or b - a < 20:
                continue
            seg = r[a:b] - np.median(r[a:b])
            m = min(seg.size, 400)
            seg = seg[:m]
            zc = int(np.sum(np.signbit(seg[1:]) != np.signbit(seg[:-1])))
            amp0 = float(np.max(np.abs(seg[: max(3, m // 4)])))
            amp1 = float(np.max(np.abs(seg[3 * m // 4:]))) if m >= 8 else amp0
            if zc >= 4 and amp0 > 3 * amp1 > 0:
                ring_score = max(ring_score, 0.8)
                ring_txt = f"; the residual rings and decays after steps ({zc} zero crossings in {m * dt * 1e3:.3g} ms)"
        coh_score, coh_txt = coherence_test(u, rc, dt)
        score = float(np.clip(max(2.0 * gain, ring_score, coh_score), 0.0, 1.0))
        if coh_score >= max(2.0 * gain, ring_score) and coh_txt:
            return score, coh_txt + ring_txt
        lag = corr(rc[1:], ud[:-1])
        return score, (f"the residual follows the input's acceleration: it explains {100 * gain:.0f} % of the "
                       f"residual variance beyond the input velocity (velocity alone {100 * r2v:.0f} %, "
                       f"corr {lag:+.2f}) → inertia/resonance of the stage{ring_txt}")


def _participation(d: np.ndarray, ex: np.ndarray) -> tuple[float, float]:
    """Least-squares participation in [0, 1] of what a mode adds (``d``) in the residual ``ex``, and the squared
    error left: ``(inf, 0)`` when ``d`` is zero or not finite (the starts' scans skip it)."""
    den = float(d @ d)
    if not (np.isfinite(den) and den > 0):
        return np.inf, 0.0
    part = float(np.clip((d @ ex) / den, 0.0, 1.0))
    r = ex - part * d
    c = float(r @ r)
    return (c if np.isfinite(c) else np.inf), part


# ------------------------------------------------------------------------------------- choosing the structure
@dataclass(frozen=True)
class StructureChoice:
    """Outcome of :func:`choose_structure`: the kept structure and each one's validation RMSE (m)."""

    structure: str
    rmse: dict[str, float]
    results: dict[str, object]


def choose_structure(base, t: np.ndarray, u: np.ndarray, y: np.ndarray, *,
                     fit: Callable | None = None, config: Mapping[str, object] | None = None,
                     structures: tuple[str, ...] = STRUCTURES, **fit_options) -> StructureChoice:
    """Fit base + dynamics in each structure and keep the one with the lower validation RMSE.

    Parameters
    ----------
    base : Model
        Base hysteresis model (its config supplies ``u_scale``, ``y_scale``).
    t, u, y : ndarray
        Record (s, input unit, m).
    fit : callable, optional
        ``fit(model, t, u, y, **fit_options) -> FitResult`` with a ``rmse`` (validation) attribute; default
        :func:`hyst_model.identify.fit`.
    config : mapping, optional
        Extra configuration (``dt``, ``dynamics.substeps``, ``dynamics.interp``).
    """
    from .compose import compose
    if fit is None:
        from ..identify import fit as default_fit
        fit = default_fit
    results: dict[str, object] = {}
    rmse: dict[str, float] = {}
    for s in structures:
        cfg = dict(config or {})
        cfg["dynamics.structure"] = s
        cfg.setdefault("dt", sample_time(np.asarray(t, float)))
        model = compose(base, [DynamicsEffect({**base.config(), **cfg})])
        res = fit(model, t, u, y, **fit_options)
        results[s] = res
        v = getattr(res, "rmse", None)
        if v is None or not np.isfinite(v):
            v = getattr(res, "rmse_train", np.inf)
        rmse[s] = float(v) if v is not None else float("inf")
    best = min(rmse, key=lambda k: rmse[k])
    return StructureChoice(best, rmse, results)
