"""Name the physical effect a model is missing: fit the base, test each effect, refit with held-out validation.

The engine (:func:`diagnose`)

1. checks the record and splits it like ``hyst fit`` does (:func:`hyst_model.identify.make_split`, default: train
   on the first 75 %, validate on the last 25 %). Models are simulated free-run from rest over the whole record;
   their parameters only ever see the training samples, so a free parameter earns nothing unless it predicts
   held-out data — and the validation RMSE at each ladder rung is the number ``hyst fit --effects`` reports;
2. estimates the sensor noise floor from the measured output (second differences, robust) — the best any model
   can do;
3. fits the base model (``mbw`` or ``bw``) with :func:`hyst_model.identify.fit`;
4. for every candidate effect computes its residual signature (a score and a sentence of evidence) and refits
   base + effect from the base fit and the effect's data-driven start. Records longer than ``screen_samples``
   are screened on a decimated copy first and only the ``full_rate_top`` best are refitted at full rate;
5. ranks candidates by validation RMSE, calls one *significant* only if it cuts the validation RMSE by at least
   ``min_factor`` and the per-block squared-error reduction is significant (paired t > ``t_min`` over 20
   validation chunks), and reports ``"none"`` when the baseline is already at the noise floor or nothing is
   significant — no false alarms;
6. builds the error ladder greedily: base → + best effect → + the next effect that still helps … with the
   validation RMSE at each rung.
"""
from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import DataError, EffectError, FitError
from ..effects import EFFECTS, compose
from ..effects.base import ComposedModel
from ..effects.signals import fmt_len, noise_floor, sample_time
from ..model import Model

__all__ = ["Candidate", "Rung", "Diagnosis", "diagnose", "validation_mask", "MIN_TRAIN", "MIN_VALID"]

#: Fewest samples for training / validation; below → FitError("too little data for validation").
MIN_TRAIN = 700
MIN_VALID = 300
#: Validation fraction (the tail of the record), as ``hyst fit``'s default.
SPLIT = 0.25


@dataclass
class Candidate:
    """One effect tested against the data.

    Attributes
    ----------
    effect : str
    rmse : float
        Validation RMSE of base + effect (m).
    rmse_train : float
    improvement : float
        Baseline validation RMSE / this RMSE (> 1 is better).
    significant : bool
        Passes the margin and the paired test.
    score : float
        Residual-signature score in [0, 1].
    evidence : str
        Why, in words.
    t_stat : float
        Paired t statistic of the squared-error reduction on validation chunks.
    params : dict
        Fitted effect parameters (namespaced).
    """

    effect: str
    rmse: float
    rmse_train: float
    improvement: float
    significant: bool
    score: float
    evidence: str
    t_stat: float = 0.0
    params: dict = field(default_factory=dict)


@dataclass
class Rung:
    """One step of the error ladder."""

    model: str
    effects: list
    rmse: float
    rmse_train: float


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`to_json` gives the ``hyst diagnose --json`` object."""

    base: str
    baseline_rmse: float
    baseline_rmse_train: float
    noise: float
    candidates: list
    missing: str
    ladder: list
    explanation: str
    n_samples: int
    dt: float
    seconds: float
    models: dict = field(default_factory=dict, repr=False)  # name → (Model, theta), for reports

    def to_json(self) -> dict:
        return {
            "baseline": {"model": self.base, "rmse": self.baseline_rmse, "rmse_train": self.baseline_rmse_train},
            "noise_floor": self.noise,
            "candidates": [{"effect": c.effect, "rmse": c.rmse, "improvement": c.improvement,
                            "significant": c.significant, "score": c.score, "evidence": c.evidence,
                            "params": c.params} for c in self.candidates],
            "missing": self.missing,
            "ladder": [asdict(r) for r in self.ladder],
            "explanation": self.explanation,
            "split": f"train on the first {1 - SPLIT:.0%}, validate on the last {SPLIT:.0%} (free run from rest)",
            "samples": self.n_samples, "dt": self.dt, "seconds": self.seconds,
        }


# --------------------------------------------------------------------------------------------------------------
def validation_mask(n: int) -> np.ndarray:
    """True on the held-out validation samples: the tail, as :func:`hyst_model.identify.make_split` cuts it."""
    from ..identify import make_split
    sp = make_split(np.arange(n, dtype=np.float64), SPLIT)
    m = np.zeros(n, dtype=bool)
    m[sp.val_start:sp.val_stop] = True
    return m


def _rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")


def _paired_t(e_base: np.ndarray, e_new: np.ndarray, chunks: int = 20) -> float:
    """t statistic of mean(e_base² − e_new²) over contiguous chunks (residuals are correlated in time)."""
    d = e_base * e_base - e_new * e_new
    parts = np.array_split(d, chunks)
    means = np.array([p.mean() for p in parts if p.size])
    if means.size < 3:
        return 0.0
    sd = float(means.std(ddof=1))
    if sd == 0.0:
        return math.inf if means.mean() > 0 else 0.0
    return float(means.mean() / (sd / math.sqrt(means.size)))


def _fit(model: Model, t, u, y, train: np.ndarray, theta0: np.ndarray | None, fitter) -> tuple[np.ndarray, np.ndarray]:
    """Fit ``model`` on the training samples; return (theta, free-run prediction over the whole record)."""
    theta = fitter(model, t, u, y, train, theta0)
    yhat = model.simulate(theta, t, u)
    if not np.all(np.isfinite(yhat)):
        raise FitError(f"{model.name}: the fitted model diverges on this record")
    return theta, yhat


def default_fitter(model: Model, t, u, y, train: np.ndarray, theta0: np.ndarray | None) -> np.ndarray:
    """Fit with :func:`hyst_model.identify.fit` on the training window; returns θ.

    Without a start (the base model) the fast method (equation-error starts + output-error least squares);
    with one (base + effect from the base fit and the effect's data-driven start) bounded least squares from it.
    """
    from .. import identify  # late: identification imports models; keep diagnose importable on its own
    if theta0 is None:
        res = identify.fit(model, t, u, y, method="fast", split=SPLIT)
    else:
        res = identify.fit(model, t, u, y, method="lsq", split=SPLIT, theta0=theta0, max_nfev=60)
    return np.asarray(res.theta, dtype=np.float64)


def _scales(u: np.ndarray, y: np.ndarray) -> dict:
    """Normalisation for the base model (:func:`hyst_model.models.data_config`)."""
    from ..models import data_config
    if not (np.ptp(u) > 0 and np.ptp(y) > 0):
        raise DataError("the input or the output never changes: nothing to identify")
    return data_config(u, y)


class _Progress:
    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total, self.i, self.t0 = enabled, total, 0, time.perf_counter()

    def __call__(self, msg: str, step: bool = True) -> None:
        if step:
            self.i += 1
        if self.enabled:
            print(f"[diagnose {self.i}/{self.total} {time.perf_counter() - self.t0:5.1f}s] {msg}",
                  file=sys.stderr, flush=True)


def candidate_names(base_model: Model, names: Sequence[str] | None = None) -> list[str]:
    """Effects that can extend ``base_model`` (all registered ones, or the given ones after checking)."""
    pool = list(names) if names else sorted(EFFECTS)
    out = []
    for n in pool:
        if n not in EFFECTS:
            raise EffectError(f"unknown effect {n!r}; choose from {', '.join(sorted(EFFECTS))}")
        try:
            compose(base_model, [n])
        except EffectError:
            if names:
                raise
            continue
        out.append(n)
    return out


def diagnose(t, u, y, *, base: str = "mbw", effects: Sequence[str] | None = None, fitter=None,
             min_factor: float = 1.1, t_min: float = 3.0, noise_margin: float = 1.25,
             screen_samples: int = 20000, full_rate_top: int = 3, max_rungs: int = 3,
             progress: bool | Callable = False) -> Diagnosis:
    """Fit ``base``, test each effect by its residual signature and a validated refit, name the missing one.

    Parameters
    ----------
    t, u, y : array_like
        Sample times (s), input (V) and measured output (m), regularly sampled.
    base : {"mbw", "bw"}
    effects : sequence of str, optional
        Candidates; default every registered effect that applies to ``base``.
    fitter : callable, optional
        ``fitter(model, t, u, y, train_mask, theta0) -> theta``; default :func:`default_fitter`.
    min_factor : float
        A candidate must divide the validation RMSE by at least this much.
    t_min : float
        ... and reduce the squared error with paired t above this over validation chunks.
    noise_margin : float
        Baseline validation RMSE below ``noise_margin × noise floor`` → nothing is missing.
    screen_samples : int
        Longer records are screened on a decimated copy of about this many samples.
    full_rate_top : int
        How many screened candidates are refitted at full rate.
    max_rungs : int
        Effects in the ladder at most.
    progress : bool or callable
        Print progress lines on stderr.

    Raises
    ------
    DataError, FitError, EffectError
        Unusable data, too little data for validation, unknown or non-applicable effect.
    """
    from ..spec import build_model

    t0 = time.perf_counter()
    t = np.asarray(t, dtype=np.float64).ravel()
    u = np.asarray(u, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    if not (t.size == u.size == y.size):
        raise DataError(f"t, u, y have different lengths ({t.size}, {u.size}, {y.size})")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise DataError("the record contains non-finite values")
    n = t.size
    val = validation_mask(n)
    if (~val).sum() < MIN_TRAIN or val.sum() < MIN_VALID:
        raise FitError(f"too little data for validation: {n} samples; diagnose needs at least "
                       f"{int(np.ceil((MIN_TRAIN + MIN_VALID) / 1.0))} (30 % are held out)")
    fitter = fitter or default_fitter
    dt = sample_time(t)
    cfg = dict(_scales(u, y), dt=dt)
    cfg["drift.span"] = float(t[~val][-1] - t[0])  # drift knots cover the training span
    base_model = build_model(base, (), cfg)
    names = candidate_names(base_model, effects)
    q = max(1, int(math.ceil(n / screen_samples)))
    n_steps = 2 + len(names) + (min(full_rate_top, len(names)) if q > 1 else 0) + max_rungs
    say = progress if callable(progress) else _Progress(bool(progress), n_steps)

    noise = noise_floor(y)
    train = ~val

    # --- screening level: decimated copy for long records -------------------------------------------------
    def level(tt, uu, yy):
        vv = validation_mask(tt.size)
        bm = build_model(base, (), dict(cfg, dt=sample_time(tt)))
        th, yh = _fit(bm, tt, uu, yy, ~vv, None, fitter)
        return vv, bm, th, yh

    say(f"fitting base model {base} on {n} samples ({(~val).sum()} train, {val.sum()} validation)")
    vs, bm_full, th_base, yh_base = level(t, u, y)
    e_base = y - yh_base
    base_val, base_tr = _rmse(e_base[val]), _rmse(e_base[train])
    say(f"base {base}: validation RMSE {fmt_len(base_val)}, noise floor {fmt_len(noise)}", step=False)

    if q > 1:
        ts, us, ys = t[::q], u[::q], y[::q]
        say(f"screening on a 1:{q} decimated copy ({ts.size} samples)")
        vs_s, bm_s, th_s, yh_s = level(ts, us, ys)
    else:
        ts, us, ys, vs_s, bm_s, th_s, yh_s = t, u, y, val, bm_full, th_base, yh_base
    e_s = ys - yh_s
    base_val_s = _rmse(e_s[vs_s])

    cands: dict[str, Candidate] = {}
    fitted: dict[str, tuple] = {}
    screened: list[tuple[float, str]] = []
    for name in names:
        tc = time.perf_counter()
        m = compose(bm_s, [name], cfg)
        try:
            score, ev = m.effects[-1].signature(ts, us, e_s, sample_time(ts))
        except Exception as err:  # noqa: BLE001 - a user effect's test must not sink the diagnosis
            score, ev = 0.0, f"signature failed ({type(err).__name__}: {err})"
        try:
            th0 = m.start(ts, us, ys, th_s)
            th, yh = _fit(m, ts, us, ys, ~vs_s, th0, fitter)
            r = _rmse((ys - yh)[vs_s])
        except FitError as err:
            r, th = math.inf, None
            ev = f"{ev}; refit failed: {err}"
        screened.append((r, name))
        cands[name] = Candidate(name, r, math.nan, base_val_s / r if r > 0 else math.inf, False,
                                float(score), ev)
        fitted[name] = (m, th)
        say(f"{base}+{name}: validation RMSE {fmt_len(r)} ({base_val_s / r:.2f}×), signature {score:.2f}, "
            f"{time.perf_counter() - tc:.1f} s")

    # --- full rate for the best screened candidates -------------------------------------------------------
    screened.sort()
    if q > 1:
        keep = [nm for r, nm in screened[:full_rate_top] if np.isfinite(r)]
        for nm in [x for _, x in screened[full_rate_top:]]:
            c = cands[nm]
            c.rmse = c.rmse / base_val_s * base_val  # scaled estimate, marked as screened in the evidence
            c.evidence += " (screened on decimated data only)"
        for name in keep:
            m = compose(bm_full, [name], cfg)
            th0 = m.start(t, u, y, th_base)
            _carry(th0, m, fitted[name])
            try:
                th, yh = _fit(m, t, u, y, train, th0, fitter)
            except FitError:
                th, yh = th0, m.simulate(th0, t, u)
            fitted[name] = (m, th)
            say(f"full rate {base}+{name}: validation RMSE {fmt_len(_rmse((y - yh)[val]))}")
    # Final numbers at full rate for everything refitted there.
    for name, (m, th) in list(fitted.items()):
        c = cands[name]
        if th is None or (q > 1 and name not in [x for _, x in screened[:full_rate_top]]):
            continue
        e = y - m.simulate(th, t, u)
        c.rmse, c.rmse_train = _rmse(e[val]), _rmse(e[train])
        c.improvement = base_val / c.rmse if c.rmse > 0 else math.inf
        c.t_stat = _paired_t(e_base[val], e[val])
        c.params = {k: v for k, v in m.unpack(th).items() if "." in k}
    at_floor = base_val <= noise_margin * noise
    for c in cands.values():
        c.significant = bool(not at_floor and c.improvement >= min_factor and c.t_stat >= t_min)
        c.evidence = _explain(c, base, base_val)
    ranked = sorted(cands.values(), key=lambda c: (not c.significant, c.rmse))

    # --- error ladder -------------------------------------------------------------------------------------
    ladder = [Rung(base, [], base_val, base_tr)]
    models = {base: (bm_full, th_base)}
    chosen: list[str] = []
    if not at_floor and ranked and ranked[0].significant:
        best = ranked[0]
        m, th = fitted[best.effect]
        chosen.append(best.effect)
        ladder.append(Rung(m.name, list(chosen), best.rmse, best.rmse_train))
        models[m.name] = (m, th)
        cur_val, cur_e = best.rmse, y - m.simulate(th, t, u)
        pool = [c.effect for c in ranked[1:] if c.significant or c.improvement >= 1.02]
        while pool and len(chosen) < max_rungs:
            trial = []
            for nm in pool:
                try:
                    mm = compose(bm_full, chosen + [nm], cfg)
                except EffectError:
                    continue
                th0 = mm.start(t, u, y, th_base)
                _carry(th0, mm, models[ladder[-1].model])
                _carry(th0, mm, fitted[nm])
                try:
                    tth, yh = _fit(mm, t, u, y, train, th0, fitter)
                except FitError:
                    continue
                e = y - yh
                trial.append((_rmse(e[val]), nm, mm, tth, e))
                say(f"ladder {mm.name}: validation RMSE {fmt_len(trial[-1][0])}")
            if not trial:
                break
            r, nm, mm, tth, e = min(trial, key=lambda x: x[0])
            if not (cur_val / r >= min_factor and _paired_t(cur_e[val], e[val]) >= t_min
                    and cur_val > noise_margin * noise):
                break
            chosen.append(nm)
            ladder.append(Rung(mm.name, list(chosen), r, _rmse(e[train])))
            models[mm.name] = (mm, tth)
            cur_val, cur_e = r, e
            pool.remove(nm)
    missing = chosen[0] if chosen else "none"
    if at_floor:
        expl = (f"the {base} model already predicts held-out data to {fmt_len(base_val)} RMS, at the sensor "
                f"noise floor ({fmt_len(noise)}): no effect is missing")
    elif not chosen:
        expl = (f"the {base} model leaves {fmt_len(base_val)} RMS (noise floor {fmt_len(noise)}), but no candidate "
                f"effect predicts held-out data significantly better (needs ≥ {min_factor:g}× and paired t ≥ "
                f"{t_min:g}); the remaining error is not one of: {', '.join(names)}")
    else:
        expl = " → ".join(f"{r.model} {fmt_len(r.rmse)}" for r in ladder)
    return Diagnosis(base, base_val, base_tr, noise, ranked, missing, ladder, expl, n, dt,
                     time.perf_counter() - t0, models)


def _carry(theta: np.ndarray, into: ComposedModel, source) -> None:
    """Copy same-named effect parameters of an earlier fit into ``theta`` (warm start), in place."""
    m, th = source
    if th is None:
        return
    vals = {k: v for k, v in m.unpack(th).items() if "." in k}
    names = into.names
    for k, v in vals.items():
        if k in names:
            theta[names.index(k)] = v


def _explain(c: Candidate, base: str, base_val: float) -> str:
    head = (f"adding {c.effect} changes the validation RMSE from {fmt_len(base_val)} to {fmt_len(c.rmse)} "
            f"({c.improvement:.2f}×)")
    tail = c.evidence.split("; adding ")[0]
    verdict = "significant" if c.significant else "not significant"
    return f"{head}, {verdict}; {tail}"
