"""Name the physical effect a model is missing: fit the base, test each effect, refit with held-out validation.

The engine (:func:`diagnose`)

1. checks the record and splits it like ``hyst fit`` does by default (:func:`validation_mask`: train on 75 %,
   validate on 25 % of the samples in 8 interleaved blocks). Models are simulated free-run from rest over the
   whole record;
   their parameters only ever see the training samples, so a free parameter earns nothing unless it predicts
   held-out data — and the validation RMSE at each ladder rung is the number ``hyst fit --effects`` reports;
2. estimates the sensor noise floor from the measured output (second differences, robust) — the best any model
   can do;
3. fits the base model (``mbw`` or ``bw``) with :func:`hyst_model.identify.fit`;
4. for every candidate effect computes its residual signature (a score and a sentence of evidence) and screens
   it: the effect's few parameters (and the offset) fitted from its data-driven start on top of the base model
   held fixed (:class:`Fixed`) — cheap at full rate, where the per-sample base parameters stay valid (decimating
   would change them). Every candidate is then refitted jointly with the base (:func:`guarded_refit`), since
   the base held fixed hides effects it imitates; validation is on interleaved blocks (:func:`validation_mask`);
5. ranks candidates by validation RMSE, calls one *significant* only if it cuts the validation RMSE by at least
   ``min_factor`` and the per-chunk squared-error reduction is significant (robust paired t > ``t_min`` over 40
   validation chunks), and reports ``"none"`` when the baseline is already at the noise floor or nothing is
   significant — no false alarms. A base error at least :data:`UNEXPLAINED_FACTOR` × the noise floor that no
   effect explains is ``"unexplained"``, never ``"none"``, with the evidence whether it is the loop shape or
   something outside the library (:mod:`.unexplained`);
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
from .unexplained import UNEXPLAINED_FACTOR, Unexplained, explain_unexplained

__all__ = ["Candidate", "Rung", "Diagnosis", "diagnose", "refit", "guarded_refit", "default_fitter", "validation_mask", "candidate_names",
           "MIN_TRAIN", "MIN_VALID", "SPLIT", "BLOCKS"]

#: Fewest samples for training / validation; below → FitError("too little data for validation").
MIN_TRAIN = 700
MIN_VALID = 300
#: Validation fraction (the tail of the record), as ``hyst fit``'s default.
SPLIT = 0.25
#: Interleaved validation blocks (see :func:`validation_mask`).
BLOCKS = 8


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
    on_top_of: list = field(default_factory=list)


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
    unexplained: Unexplained | None = None  # the error left ≥ UNEXPLAINED_FACTOR × noise, described

    def to_json(self) -> dict:
        return {
            "baseline": {"model": self.base, "rmse": self.baseline_rmse, "rmse_train": self.baseline_rmse_train},
            "noise_floor": self.noise,
            "candidates": [{"effect": c.effect, "rmse": c.rmse, "improvement": c.improvement,
                            "significant": c.significant, "score": c.score, "t_stat": c.t_stat,
                            "on_top_of": c.on_top_of,
                            "evidence": c.evidence,
                            "params": c.params} for c in self.candidates],
            "missing": self.missing,
            "ladder": [asdict(r) for r in self.ladder],
            "explanation": self.explanation,
            "split": f"validate on {SPLIT:.0%} of the samples in {BLOCKS} interleaved blocks, train on the rest "
                     "(one free run from rest)",
            "samples": self.n_samples, "dt": self.dt, "seconds": self.seconds,
            "unexplained": self.unexplained.to_json() if self.unexplained else None,
        }


# --------------------------------------------------------------------------------------------------------------
def validation_mask(n: int) -> np.ndarray:
    """True on the held-out validation samples: :data:`SPLIT` of the record in :data:`BLOCKS` interleaved blocks.

    A tail hold-out validates only what the record does last — the highest frequencies of a sweep, the
    smallest triangles, one sine — so a model fitted on the rest must extrapolate there, and an effect that
    shows only elsewhere is never seen in validation. Interleaved blocks (:func:`hyst_model.identify.block_mask`)
    sample every part of the excitation; the fit never scores them (``split=mask``).
    """
    from ..identify.result import block_mask
    return block_mask(n, SPLIT, BLOCKS)


def _rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")


def _paired_t(e_base: np.ndarray, e_new: np.ndarray, chunks: int = 40) -> float:
    """Robust t statistic of the squared-error reduction mean(e_base² − e_new²) over contiguous chunks.

    Residuals are correlated in time, so the reduction is averaged per chunk. Its spread is taken from the
    median absolute deviation of the chunk means: a real effect often shows in a few chunks only (a delay only
    where the input moves), which would inflate a plain standard deviation and hide it, while chunks where
    neither model errs beyond noise measure the chance fluctuation.
    """
    d = e_base * e_base - e_new * e_new
    parts = np.array_split(d, chunks)
    means = np.array([p.mean() for p in parts if p.size])
    if means.size < 5:
        return 0.0
    scale = 1.4826 * float(np.median(np.abs(means - np.median(means))))
    scale = max(scale, 1e-3 * float(np.std(means)), 1e-300)
    return float(np.mean(means) / (scale / math.sqrt(means.size)))


def _simulate(model: Model, theta, t, u) -> np.ndarray:
    with np.errstate(all="ignore"):
        yhat = np.asarray(model.simulate(theta, t, u), dtype=np.float64)
    if not np.all(np.isfinite(yhat)):
        raise FitError(f"{model.name}: the fitted model diverges on this record")
    return yhat


def default_fitter(model: Model, t, u, y, theta0: np.ndarray | None) -> np.ndarray:
    """Fit with :func:`hyst_model.identify.fit` on the training window; returns θ.

    Without a start: the fast method (equation-error starts + output-error least squares); with one: the fast
    method's output-error Levenberg-Marquardt from it (on the hidden saturation bag it reaches the noise floor,
    2.07 nm, in 0.8 s where scipy's trust-region solver stopped at 49.5 nm after 7.3 s). Both use the same
    split, so validation numbers match ``hyst fit``.
    """
    from .. import identify  # late: identification imports models; keep diagnose importable on its own
    split = validation_mask(np.asarray(t).size)
    if theta0 is None:
        res = identify.fit(model, t, u, y, method="fast", split=split)
    else:
        res = identify.fit(model, t, u, y, method="fast", split=split, theta0=theta0, max_nfev=80)
    return np.asarray(res.theta, dtype=np.float64)


def refit(base_model: Model, names: Sequence[str], cfg: dict, t, u, y, theta_base: np.ndarray,
          carry: dict | None = None, fitter=None, two_stage: bool = True, prior: dict | None = None
          ) -> tuple[ComposedModel, np.ndarray, np.ndarray]:
    """Fit base + effects in two stages; return (model, θ, free-run prediction).

    1. Each effect's data-driven start (:meth:`Effect.start` on the base model's residual) — parameters it does
       not provide come from ``prior`` (e.g. the screening level's fit: effect parameters are physical, so they
       carry across sample rates; base parameters do not) — overridden by ``carry`` (values of an earlier fit
       at this rate, e.g. the previous rung of the ladder);
    2. for input-side effects (delay), the base refitted on the input as the effect transforms it at its start
       (a base fitted without the effect is distorted by it — its δ terms imitate a delay — and a joint fit
       from there stalls in that basin);
    3. everything jointly from there.

    With ``two_stage=False`` step 2 is skipped — for refits whose effect parameters are already good (carried
    from the screening level), where the joint fit alone converges and costs a fraction.
    """
    fitter = fitter or default_fitter
    m = compose(base_model, list(names), cfg)
    if prior:  # lowest precedence: values an effect's own start does not provide
        nm = m.names
        for e in m.effects:
            pre = {p.name: prior[f"{e.name}.{p.name}"] for p in e.params() if f"{e.name}.{p.name}" in prior}
            base_start = e.start
            e.start = (lambda f, pre: lambda *a: {**pre, **(f(*a) or {})})(base_start, pre)
    th0 = m.start(t, u, y, theta_base)
    if carry:
        nm = m.names
        for k, v in carry.items():
            if k in nm and "." in k:
                th0[nm.index(k)] = v
        lo, hi = m.bounds
        th0 = np.clip(th0, lo, hi)
    th1 = th0
    inputs = [(e, te) for e, te in zip(m.effects, m.split(th0)[1]) if e.kind == "input"]
    if two_stage and inputs:
        # The base around the input effects at their start: the base alone on the transformed input, with
        # the base model's own fast fitter (equation-error starts, exact Jacobian).
        uu = u
        for e, te in inputs:
            uu = e.input(te, t, uu)
        th1 = th0.copy()
        th1[: len(base_model.names)] = fitter(base_model, t, uu, y, None)
    th = fitter(m, t, u, y, th1)
    return m, th, _simulate(m, th, t, u)


def _point(m: Model, values: dict) -> np.ndarray:
    """Packed θ of ``m`` from named values (others at their defaults), clipped to the bounds."""
    th = np.asarray(m.theta0, dtype=np.float64).copy()
    names = m.names
    for k, v in values.items():
        if k in names and np.isfinite(v):
            th[names.index(k)] = v
    lo, hi = m.bounds
    return np.clip(th, lo, hi)


def guarded_refit(base_model: Model, names: Sequence[str], cfg: dict, t, u, y, val: np.ndarray,
                  start: dict, **refit_kw) -> tuple[ComposedModel, np.ndarray, np.ndarray]:
    """:func:`refit`, but never worse on validation than the point it starts from.

    ``start`` names the best model found so far (the base or previous rung's parameters plus the screened
    effect's values). A joint refit that ends worse than that point — a local minimum, a fitter stopped early —
    is discarded and the start kept; a refit that fails keeps the start too. Identification never goes backwards.
    """
    m = compose(base_model, list(names), cfg)
    th_s = _point(m, start)
    try:
        yh_s = _simulate(m, th_s, t, u)
    except FitError:
        yh_s = None
    try:
        m2, th, yh = refit(base_model, names, cfg, t, u, y, **refit_kw)
    except (FitError, EffectError):
        if yh_s is None:
            raise
        return m, th_s, yh_s
    if yh_s is not None and _rmse((y - yh_s)[val]) < _rmse((y - yh)[val]):
        return m, th_s, yh_s
    return m2, th, yh


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


class Fixed(Model):
    """A fitted model held fixed, except its output offset: the inner model for screening an effect on top.

    Screening an effect with everything else frozen costs a few parameters' fit at full rate (the base's
    per-sample parameters must not be decimated); the effect's own parameters plus the offset are free.
    """

    def __init__(self, model: Model, theta: np.ndarray):
        self.model, self.theta = model, np.asarray(theta, dtype=np.float64)
        self.name = model.name
        self._off = model.names.index("offset") if "offset" in model.names else None
        self._params = tuple(p for p in model.params() if p.name == "offset")
        if self._off is not None:
            p = self._params[0]
            self._params = (type(p)(p.name, float(self.theta[self._off]), p.lower, p.upper, p.unit, p.doc),)

    def params(self):
        return self._params

    def config(self):
        return self.model.config()

    def simulate(self, theta, t, u):
        th = self.theta.copy()
        if self._off is not None:
            th[self._off] = theta[0]
        return self.model.simulate(th, t, u)


def _effect_values(m: Model, th: np.ndarray, only: str | None = None) -> dict:
    return {k: v for k, v in m.unpack(th).items() if "." in k and (only is None or k.startswith(only + "."))}


def diagnose(t, u, y, *, base: str = "mbw", effects: Sequence[str] | None = None, fitter=None,
             min_factor: float = 1.1, t_min: float = 3.0, noise_margin: float = 1.25,
             unexplained_factor: float = UNEXPLAINED_FACTOR,
             full_rate_top: int = 2, max_rungs: int = 3, progress: bool | Callable = False) -> Diagnosis:
    """Fit ``base``, test each effect by its residual signature and a validated refit, name the missing one.

    Parameters
    ----------
    t, u, y : array_like
        Sample times (s), input (V) and measured output (m), regularly sampled.
    base : {"mbw", "bw"}
    effects : sequence of str, optional
        Candidates; default every registered effect that applies to ``base``.
    fitter : callable, optional
        ``fitter(model, t, u, y, theta0) -> theta`` fitting on the training window; default
        :func:`default_fitter` (:func:`hyst_model.identify.fit`).
    min_factor : float
        A candidate must divide the validation RMSE by at least this much ...
    t_min : float
        ... and reduce the squared error with a robust paired t statistic above this (40 validation chunks).
    noise_margin : float
        Baseline validation RMSE below ``noise_margin × noise floor`` → nothing is missing.
    unexplained_factor : float
        Final validation RMSE at or above this × the noise floor is described as unexplained; with no
        significant effect the verdict is then ``"unexplained"`` instead of ``"none"``.
    full_rate_top : int
        How many screened candidates get the full joint refit at each further rung of the ladder (at the first
        rung every candidate does).
    max_rungs : int
        Effects in the ladder at most.
    progress : bool or callable
        Print progress lines on stderr (or pass each line to a callable).

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
    need = int(math.ceil(max(MIN_TRAIN / (1 - SPLIT), MIN_VALID / SPLIT)))
    if n < need:
        raise FitError(f"too little data for validation: {n} samples; diagnose holds out "
                       f"{SPLIT:.0%} in {BLOCKS} blocks and needs at least {need} samples")
    val = validation_mask(n)
    train = ~val
    fit_ = fitter or default_fitter
    dt = sample_time(t)
    cfg = dict(_scales(u, y), dt=dt)
    cfg["drift.span"] = float(t[train][-1] - t[0])  # drift knots cover the span the fit scores
    base_model = build_model(base, (), cfg)
    names = candidate_names(base_model, effects)
    n_steps = 1 + 2 * len(names) + full_rate_top * max_rungs
    say = progress if callable(progress) else _Progress(bool(progress), n_steps)
    noise = noise_floor(y)

    say(f"fitting base model {base} on {n} samples ({train.sum()} train, {val.sum()} validation)")
    th_base = fit_(base_model, t, u, y, None)
    e_base = y - _simulate(base_model, th_base, t, u)
    base_val, base_tr = _rmse(e_base[val]), _rmse(e_base[train])
    at_floor = base_val <= noise_margin * noise
    say(f"base {base}: validation RMSE {fmt_len(base_val)}, noise floor {fmt_len(noise)}"
        + (" (at the noise floor)" if at_floor else ""), step=False)

    def screen_on(inner: Model, th_inner: np.ndarray, chosen: list[str], nm: str, prior: dict | None):
        """Fit only effect ``nm`` (+ offset) on top of a fixed inner model; return (val RMSE, effect values)."""
        if compose(base_model, [nm], cfg).effects[-1].screen_with_refit():
            # replaces the base recursion (configuration may decide it), or transforms its input: a base fitted
            # without the effect imitates it (its δ terms mimic a delay), so with the base held fixed the effect
            # looks useless — only a refit with the base on the transformed input can tell
            m, th, yh = refit(base_model, chosen + [nm], cfg, t, u, y, th_base, prior, fit_)
            return _rmse((y - yh)[val]), _effect_values(m, th, nm), (m, th, y - yh)
        fx = Fixed(inner, th_inner)
        m = compose(fx, [nm], cfg)
        th0 = m.start(t, u, y, fx.theta0)
        if prior:
            for k, v in prior.items():
                if k in m.names:
                    th0[m.names.index(k)] = v
        th = fit_(m, t, u, y, np.clip(th0, *m.bounds))
        vals = _effect_values(m, th, nm)
        if "offset" in m.names:  # the screen refits the offset too: part of the point a refit starts from
            vals["offset"] = float(th[m.names.index("offset")])
        return _rmse((y - _simulate(m, th, t, u))[val]), vals, None

    # --- screening: each candidate alone on top of the fitted base ----------------------------------------
    cands: dict[str, Candidate] = {}
    carry: dict[str, dict] = {}
    full: dict[str, tuple] = {}
    for nm in names:
        tc = time.perf_counter()
        probe = compose(base_model, [nm], cfg)
        try:
            score, ev = probe.effects[-1].signature(t, u, e_base, dt)
            score = float(np.clip(score, 0.0, 1.0))
        except Exception as err:  # noqa: BLE001 - a user effect's test must not sink the diagnosis
            score, ev = 0.0, f"its residual test failed ({type(err).__name__}: {err})"
        variants = list(getattr(EFFECTS[nm], "variants", lambda: [{}])()) or [{}]
        tried: list[tuple[float, dict, dict, tuple | None]] = []
        errors = []
        for var in variants:  # e.g. dynamics in both structures: keep whichever validates better
            cfg.update(var)  # an effect reads only its own "<name>.*" keys, so the shared config can carry it
            try:
                r_v, vals_v, done_v = screen_on(base_model, th_base, [], nm, None)
                tried.append((r_v, var, vals_v, done_v))
            except (FitError, EffectError) as err:
                errors.append(str(err))
        if tried:
            r, var, vals, done = min(tried, key=lambda x: x[0])
            cfg.update(var)
            carry[nm] = vals
            if done is not None:
                full[nm] = done
            if len(tried) > 1:
                def _lbl(vv: dict) -> str:
                    return ", ".join(f"{k.split('.', 1)[-1]} {v}" for k, v in vv.items())
                ev += ("; tried " + " and ".join(f"{_lbl(vv)} ({fmt_len(rv)} on validation)"
                                                 for rv, vv, _, _ in tried) + f": kept {_lbl(var)}")
        else:
            r = math.inf
            ev = f"{ev}; the fit failed: {'; '.join(errors)}"
        cands[nm] = Candidate(nm, r, math.nan, base_val / r if r > 0 else math.inf, False, score, ev,
                              params=carry.get(nm, {}))
        say(f"screen {base}+{nm}: validation RMSE {fmt_len(r)} ({base_val / r:.2f}×), residual test "
            f"{score:.2f}, {time.perf_counter() - tc:.1f} s")

    # --- full joint refit of the best screened candidates -------------------------------------------------
    order = sorted(cands.values(), key=lambda c: c.rmse)
    # Every candidate gets the joint refit: screened with the base held fixed, an effect the base partly imitates
    # (an output nonlinearity its ψ/α terms bend towards, a delay its δ terms mimic) can look useless, or even
    # worse than the base, and still take the error to the noise floor once refitted with it (the hidden
    # asymmetry bag: 0.95x screened, 27x refitted).
    for c in order:
        if c.effect in full or not np.isfinite(c.rmse):
            continue
        try:
            m, th, yh = guarded_refit(base_model, [c.effect], cfg, t, u, y, val,
                                      {**base_model.unpack(th_base), **carry.get(c.effect, {})},
                                      theta_base=th_base, fitter=fit_, prior=carry.get(c.effect))
        except (FitError, EffectError):
            continue
        full[c.effect] = (m, th, y - yh)
        say(f"refit {m.name}: validation RMSE {fmt_len(_rmse((y - yh)[val]))}")
    for c in order:
        if c.effect not in full:
            c.evidence += " (screened with the base model held fixed: its joint refit failed)"
    for nm, (m, th, e) in full.items():
        c = cands[nm]
        # The refit started from the screened point and kept it if it could not improve on it, so its numbers
        # (and its paired test) stand for the candidate even where the screen's offset differed slightly.
        c.rmse, c.rmse_train = _rmse(e[val]), _rmse(e[train])
        c.improvement = base_val / c.rmse if c.rmse > 0 else math.inf
        c.t_stat = _paired_t(e_base[val], e[val])
        c.params = _effect_values(m, th)
        carry[nm] = c.params
    for c in cands.values():
        c.significant = bool(not at_floor and c.effect in full and c.improvement >= min_factor
                             and c.t_stat >= t_min)
    ranked = sorted(cands.values(), key=lambda c: (not c.significant, c.rmse))

    # --- error ladder -------------------------------------------------------------------------------------
    ladder = [Rung(base, [], base_val, base_tr)]
    models: dict[str, tuple] = {base: (base_model, th_base)}
    chosen: list[str] = []
    if ranked and ranked[0].significant:
        best = ranked[0]
        m, th, e = full[best.effect]
        chosen.append(best.effect)
        ladder.append(Rung(m.name, list(chosen), best.rmse, best.rmse_train))
        models[m.name] = (m, th)
        cur_e = e
        while len(chosen) < max_rungs:
            cur_val = _rmse(cur_e[val])
            if cur_val <= noise_margin * noise:
                break
            # A second effect is often masked by the first when tested alone: screen every remaining one on
            # top of the current rung, then refit the best at full rate.
            prev_m, prev_th = models[ladder[-1].model]
            trial_s = []
            for nm in names:
                if nm in chosen:
                    continue
                try:
                    compose(base_model, chosen + [nm], cfg)
                    r_s, vals, _ = screen_on(prev_m, prev_th, chosen, nm, carry.get(nm))
                except (EffectError, FitError):
                    continue
                trial_s.append((r_s, nm, vals))
                say(f"screen {prev_m.name}+{nm}: validation RMSE {fmt_len(r_s)}", step=False)
            trial_s.sort(key=lambda x: x[0])
            trial = []
            for r_s, nm, vals in trial_s[:full_rate_top]:
                if not cur_val / r_s >= 1.0:
                    continue
                try:
                    mm, tth, yh = guarded_refit(base_model, chosen + [nm], cfg, t, u, y, val,
                                                {**prev_m.unpack(prev_th), **vals},
                                                theta_base=prev_m.split(prev_th)[0],
                                                carry=_effect_values(prev_m, prev_th), fitter=fit_, prior=vals)
                except (EffectError, FitError):
                    continue
                trial.append((_rmse((y - yh)[val]), nm, mm, tth, y - yh))
                say(f"refit {mm.name}: validation RMSE {fmt_len(trial[-1][0])}")
            if not trial:
                break
            r, nm, mm, tth, e = min(trial, key=lambda x: x[0])
            if not (cur_val / r >= min_factor and _paired_t(cur_e[val], e[val]) >= t_min):
                break
            c = cands[nm]
            c.on_top_of, c.rmse, c.rmse_train = list(chosen), r, _rmse(e[train])
            c.improvement, c.t_stat, c.significant = cur_val / r, _paired_t(cur_e[val], e[val]), True
            c.params = _effect_values(mm, tth, nm)
            chosen.append(nm)
            ladder.append(Rung(mm.name, list(chosen), r, _rmse(e[train])))
            models[mm.name] = (mm, tth)
            cur_e = e
    # Best first: the ladder's effects in the order they were added, then the rest by validation RMSE.
    ranked = [cands[nm] for nm in chosen] + sorted((c for c in cands.values() if c.effect not in chosen),
                                                   key=lambda c: (not c.significant, c.rmse))
    rung_val = {tuple(rg.effects): rg.rmse for rg in ladder}
    for c in ranked:
        c.evidence = _explain(c, base, rung_val.get(tuple(c.on_top_of), base_val))
    missing = chosen[0] if chosen else "none"
    left = ladder[-1].rmse
    unexplained = None
    if left >= unexplained_factor * noise:
        e_last = y - _simulate(*models[ladder[-1].model], t, u)
        # Learn the loop-shape function on the first half of the held-out samples, test it on the second: both
        # halves are out of sample for the model (its training residual is fitted away and says little).
        vi = np.flatnonzero(val)
        first = np.zeros(vi.size, dtype=bool)
        first[: vi.size // 2] = True
        unexplained = explain_unexplained(u[vi], e_last[vi], first, left, noise, base,
                                          [nm for nm in names if nm not in chosen])
        if not chosen:
            missing = "unexplained"
    if at_floor:
        expl = (f"the {base} model already predicts held-out data to {fmt_len(base_val)} RMS, at the sensor "
                f"noise floor ({fmt_len(noise)}): no effect is missing")
    elif not chosen:
        expl = (f"the {base} model leaves {fmt_len(base_val)} RMS (noise floor {fmt_len(noise)}), but no candidate "
                f"predicts held-out data significantly better (needs ≥ {min_factor:g}× and paired t ≥ {t_min:g}); "
                f"the remaining error is none of: {', '.join(names)}")
        if unexplained is not None:
            expl = f"unexplained ({unexplained.kind}): {unexplained.evidence}"
    else:
        expl = " → ".join(f"{r.model} {fmt_len(r.rmse)}" for r in ladder)
        expl += (" (at the noise floor)" if left <= noise_margin * noise else
                 f" (still {left / noise:.1f}× the noise floor: something else is missing too)")
        if unexplained is not None:
            expl += f"; what is left is {unexplained.kind}: {unexplained.evidence}"
    return Diagnosis(base, base_val, base_tr, noise, ranked, missing, ladder, expl, n, dt,
                     time.perf_counter() - t0, models, unexplained)


def _explain(c: Candidate, base: str, base_val: float) -> str:
    onto = "+".join([base] + c.on_top_of)
    head = (f"adding {c.effect} to {onto} changes the validation RMSE from {fmt_len(base_val)} to "
            f"{fmt_len(c.rmse)} ({c.improvement:.2f}×)")
    tail = c.evidence.split("; adding ")[0]
    verdict = "significant" if c.significant else "not significant"
    return f"{head}, {verdict}; {tail}"
