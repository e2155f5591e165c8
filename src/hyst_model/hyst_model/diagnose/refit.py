"""The fitting machinery of :func:`hyst_model.diagnose.diagnose.diagnose`: the hold-out, the paired test, refits.

Every refit starts from the best point found so far and returns a model no worse on validation than that start
(:func:`guarded_refit`); effects are screened on top of a fitted model held fixed (:class:`Fixed`).
"""
from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import DataError, EffectError, FitError
from ..identify.result import rmse
from ..effects import EFFECTS, compose
from ..effects.compose import around_effects
from ..effects.base import ComposedModel
from ..model import Model

__all__ = ["MIN_TRAIN", "MIN_VALID", "SPLIT", "BLOCKS", "validation_mask", "default_fitter", "refit",
           "guarded_refit", "candidate_names", "Fixed", "paired_t", "rmse"]

#: Fewest samples for training / validation; below → FitError("too little data for validation").
MIN_TRAIN = 700
MIN_VALID = 300
#: Validation fraction, held out in :data:`BLOCKS` interleaved blocks (as ``hyst fit``'s default).
SPLIT = 0.25
#: Interleaved validation blocks (see :func:`validation_mask`).
BLOCKS = 8



def validation_mask(n: int, u: np.ndarray | None = None) -> np.ndarray:
    """True on the held-out validation samples: :data:`SPLIT` of the record in :data:`BLOCKS` interleaved blocks.

    A tail hold-out validates only what the record does last — the highest frequencies of a sweep, the
    smallest triangles, one sine — so a model fitted on the rest must extrapolate there, and an effect that
    shows only elsewhere is never seen in validation. Interleaved blocks (:func:`hyst_model.identify.block_mask`)
    sample every part of the excitation; the fit never scores them (``split=mask``). With the input ``u`` (as
    diagnose and ``hyst fit`` pass it) the blocks are placed to hold a fair share of its changes.
    """
    from ..identify.result import block_mask
    return block_mask(n, SPLIT, BLOCKS, u)


def paired_t(e_base: np.ndarray, e_new: np.ndarray, chunks: int = 40) -> float:
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
    # The input the fitter is given: the record's, or (the base refitted around input-side effects) that input
    # through them, whose changes are the record's moved by a few samples — the same blocks but for a share on
    # the very edge of block_phase's band, and then only the start of the joint fit trains on the other grid.
    split = validation_mask(np.asarray(t).size, np.asarray(u, dtype=np.float64))
    if theta0 is None:
        res = identify.fit(model, t, u, y, method="fast", split=split)
    else:
        res = identify.fit(model, t, u, y, method="fast", split=split, theta0=theta0, max_nfev=80)
    return np.asarray(res.theta, dtype=np.float64)


def refit(base_model: Model, names: Sequence[str], cfg: dict, t, u, y, theta_base: np.ndarray,
          carry: dict | None = None, fitter=None, two_stage: bool = True, prior: dict | None = None
          ) -> tuple[ComposedModel, np.ndarray, np.ndarray]:
    """Fit base + effects in two stages; return (model, θ, free-run prediction).

    1. Each effect's data-driven start (:meth:`Effect.start` on the base model's residual; for effects joining
       others whose values are carried, on the residual of the base and those: :func:`_start_on_carried`) —
       parameters it does not provide come from ``prior`` (e.g. the screening level's fit: effect parameters are
       physical, so they carry across sample rates; base parameters do not) — overridden by ``carry`` (values of
       an earlier fit at this rate, e.g. the previous rung of the ladder);
    2. for input-side effects (delay), the base refitted on the input as the effect transforms it at its start,
       and for output-side effects that can be undone (an output delay: :meth:`Effect.undo_output`) on the output
       without them (a base fitted without the effect is distorted by it — its δ terms imitate a delay — and a
       joint fit from there stalls in that basin);
    3. everything jointly from there;
    4. with ``two_stage``, also steps 2–3 from each effect's start read off the record alone
       (:meth:`Effect.record_start`: a drift the base absorbed, which its residual no longer shows; the base
       refitted on the output without it there), for effects whose values are not carried; the fit that trains
       better is returned.

    With ``two_stage=False`` step 2 is skipped — for refits whose effect parameters are already good (carried
    from the screening level), where the joint fit alone converges and costs a fraction.
    """
    fitter = fitter or default_fitter
    m = compose(base_model, list(names), cfg)
    if prior:  # lowest precedence: values an effect's own start does not provide
        for e in m.effects:
            pre = {p.name: prior[f"{e.name}.{p.name}"] for p in e.params() if f"{e.name}.{p.name}" in prior}
            # Per instance, so every later m.start (the fitter's too) sees it; setattr: mypy forbids assigning
            # to a method, and this override is deliberate.
            setattr(e, "start", _start_with_prior(e.start, pre))
    th0 = m.start(t, u, y, theta_base)
    if carry:
        nm = m.names
        for k, v in carry.items():
            if k in nm and "." in k:
                th0[nm.index(k)] = v
        lo, hi = m.bounds
        th0 = np.clip(th0, lo, hi)
        th0 = _start_on_carried(m, base_model, cfg, t, u, y, th0, carry)
    th = _two_stage(m, base_model, t, u, y, th0, fitter, two_stage, False)
    if two_stage:
        # Effects a base fitted without them can absorb offer a start read from the record alone (drift:
        # Effect.record_start); the refit from each is kept if it trains better (a multi-start of the same fit).
        scored = ~validation_mask(np.asarray(t).size, np.asarray(u, dtype=np.float64))
        carried = {k.split(".")[0] for k in (carry or {}) if "." in k}
        try:
            others = m.record_starts(t, u, y, th0, scored, skip=tuple(carried))
        except (EffectError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            others = []  # an effect that cannot read its record start: the first start's fit stands
        if others:
            best = _train_rmse(m, th, t, u, y, scored)
            for th_alt in others:
                try:
                    th2 = _two_stage(m, base_model, t, u, y, th_alt, fitter, two_stage, True)
                except (FitError, EffectError):
                    continue  # the first start's fit stands
                c2 = _train_rmse(m, th2, t, u, y, scored)
                if c2 < best:
                    th, best = th2, c2
    return m, th, _simulate(m, th, t, u)


def _two_stage(m: ComposedModel, base_model: Model, t, u, y, th0: np.ndarray, fitter, two_stage: bool,
               record: bool) -> np.ndarray:
    """Steps 2 and 3 of :func:`refit` from the start ``th0`` (``record``: a record start, :func:`around_effects`)."""
    th1 = th0
    uu, yy = around_effects(m, th0, t, u, y, record) if two_stage else (u, y)
    if uu is not u or yy is not y:
        # The base around the effects at their start: the base alone on the transformed input and the undone
        # output, with the base model's own fast fitter (equation-error starts, exact Jacobian).
        th1 = th0.copy()
        th1[: len(base_model.names)] = fitter(base_model, t, uu, yy, None)
    return fitter(m, t, u, y, th1)


def _train_rmse(m: Model, th: np.ndarray, t, u, y, scored: np.ndarray) -> float:
    """Training RMSE of ``m`` at ``th`` (inf where it diverges)."""
    try:
        return rmse((np.asarray(y) - _simulate(m, th, t, u))[scored])
    except FitError:
        return float("inf")


def _start_on_carried(m: ComposedModel, base_model: Model, cfg: dict, t, u, y, th0: np.ndarray, carry: dict
                      ) -> np.ndarray:
    """``th0`` with the start of each effect that ``carry`` gives no values for taken again, on the residual of the
    base and the carried effects at their carried values (not of the base alone).

    A rung's refit adds one effect to effects already fitted: its data start read from the base's residual sees
    the rung's effects there too (generated PEA stage 3000102, a gain kink behind log creep on steps: the kink's
    level and slope were read off the creep transients and the joint refit ended at 38.8 nm, worse than the creep
    rung's own 17.6 nm).
    """
    carried = [e.name for e in m.effects if any(k.startswith(e.name + ".") for k in carry)]
    fresh = [e for e in m.effects if e.name not in carried]
    if not carried or not fresh:
        return th0
    try:
        mc = compose(base_model, carried, cfg)
        vals = m.unpack(th0)
        yc = mc.simulate(mc.pack({k: vals[k] for k in mc.names}), t, u)
    except (EffectError, FitError):
        return th0
    if not np.all(np.isfinite(yc)):
        return th0
    residual = np.asarray(y, dtype=np.float64) - yc
    th = th0.copy()
    names = m.names
    for e in fresh:
        guess = e.start(t, u, y, residual) or {}
        for k, v in guess.items():
            key = f"{e.name}.{k}"
            if key in names and np.isfinite(v):
                th[names.index(key)] = v
    lo, hi = m.bounds
    return np.clip(th, lo, hi)


def _start_with_prior(start: Callable[..., dict[str, float] | None], pre: dict[str, float]
                      ) -> Callable[..., dict[str, float]]:
    """``start`` (an :meth:`Effect.start`) with the values it does not provide taken from ``pre``."""
    return lambda *a: {**pre, **(start(*a) or {})}


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
    if yh_s is not None and rmse((y - yh_s)[val]) < rmse((y - yh)[val]):
        return m, th_s, yh_s
    return m2, th, yh


def _scales(u: np.ndarray, y: np.ndarray) -> dict:
    """Normalisation for the base model (:func:`hyst_model.models.data_config`)."""
    from ..models import data_config
    if not (np.ptp(u) > 0 and np.ptp(y) > 0):
        raise DataError("the input or the output never changes: nothing to identify")
    return data_config(u, y)


class _Progress:
    """``[diagnose i/total seconds] message`` on stderr. ``total`` is an estimate that the stages raise as they
    learn their work; a rung's variants can still outnumber it, and the count then never reads past the total."""

    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total, self.i, self.t0 = enabled, total, 0, time.perf_counter()

    def __call__(self, msg: str, step: bool = True) -> None:
        if step:
            self.i += 1
            self.total = max(self.total, self.i)
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
