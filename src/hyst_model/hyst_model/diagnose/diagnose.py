"""Name the physical effect a model is missing: fit the base, test each effect, refit with held-out validation.

The engine (:func:`diagnose`)

1. checks the record and splits it like ``hyst fit`` does by default (:func:`validation_mask`: train on 75 %,
   validate on 25 % of the samples in 8 interleaved blocks). Models are simulated free-run from rest over the
   whole record;
   their parameters only ever see the training samples, so a free parameter earns nothing unless it predicts
   held-out data — and the validation RMSE at each ladder rung is the number ``hyst fit --effects`` reports;
2. estimates the sensor noise floor from the measured output (second differences, robust) with any line the
   input does not drive (mains pickup, :mod:`.lines`), or the noise read where the input is held still when that
   is larger (noise that is not white, :mod:`.colour`) — the best any model can do;
3. fits the base model (``mbw`` or ``bw``) with :func:`hyst_model.identify.fit`;
4. for every candidate effect computes its residual signature (a score and a sentence of evidence) and screens
   it: the effect's few parameters (and the offset) fitted from its data-driven start on top of the base model
   held fixed (:class:`Fixed`) — cheap at full rate, where the per-sample base parameters stay valid (decimating
   would change them). Every candidate is then refitted jointly with the base (:func:`guarded_refit`), since
   the base held fixed hides effects it imitates; validation is on interleaved blocks (:func:`validation_mask`).
   The base alone is refitted from the best joint refits' base parameters and replaced where that validates
   better (:func:`~.stages.rebase`: a base in a poor basin otherwise makes any effect look significant);
5. ranks candidates by validation RMSE, calls one *significant* only if it cuts the validation RMSE by at least
   ``min_factor`` and the per-chunk squared-error reduction is significant (robust paired t > ``t_min`` over 40
   validation chunks), and reports ``"none"`` when the baseline is already at the noise floor or nothing is
   significant — no false alarms. A base error at least :data:`UNEXPLAINED_FACTOR` × the noise floor that no
   effect explains is ``"unexplained"``, never ``"none"``, with the evidence whether it is the loop shape or
   something outside the library (:mod:`.unexplained`) — except below 5× the floor where the base fits its
   training samples at the floor: then the error lies only where the held-out blocks go beyond what training
   shows, the record does not determine the base there, and the answer is ``"none"`` with that caution and where
   the error lies (:func:`~.adequacy.held_out_only`);
6. builds the error ladder greedily: base → + best effect → + the next effect that still helps … with the
   validation RMSE at each rung — where no refit validates better but the rung's training error exceeds its
   validation error (the blocks miss where an effect acts: the largest excursions), by the same test on the
   training part (:func:`~.blind.training_only`) —, then takes the backward step of stepwise regression
   (:mod:`.prune`): an effect the others make unnecessary is dropped again; the exchange step (:mod:`.swap`)
   replaces an effect by a simpler one, and the configuration step (:mod:`.reconfig`) refits each effect of
   the final model in its other configurations (taken only when significantly better).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from hyst_common.blas import one_blas_thread

from ..effects import effects_data_config
from ..effects.settle import settle
from ..effects.quantised import lattice_step
from ..effects.signals import record_floor_step, sample_time, fmt_len
from ..errors import DataError, FitError
from .refit import (BLOCKS, MIN_TRAIN, MIN_VALID, SPLIT, Fixed, _Progress, _scales, _simulate, candidate_names,
                    default_fitter, guarded_refit, refit, rmse, validation_mask)
from .adequacy import base_caution, held_out_only
from .parallel import default_jobs
from .prune import prune
from .reconfig import reconfigure
from .swap import swap
from .jointly import joint_pair
from .colour import HINT_BELOW as COLOUR_HINT
from .floor import read_floor
from .lines import disturbance_lines, said as lines_said, without_lines
from .ladder import climb
from .setup import Candidate, Rung, Setup
from .stages import refit_all, screen_all
from .verdict import verdict
from .undetermined import sentence, undetermined
from .unexplained import UNEXPLAINED_FACTOR, Unexplained

__all__ = ["Candidate", "Rung", "Diagnosis", "diagnose", "refit", "guarded_refit", "default_fitter",
           "validation_mask", "candidate_names", "Fixed", "MIN_TRAIN", "MIN_VALID", "SPLIT", "BLOCKS"]


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
    caution: str | None = None  # the base does not carry over to the hold-out: the record may not determine it
    undetermined: list = field(default_factory=list)  # effects the record cannot tell apart (.undetermined)
    #: The white part of the floor (second differences) and the output's lines the input does not drive
    #: (.lines); ``noise`` is the floor they make with the holds' reading or the value given (.floor).
    noise_white: float | None = None
    disturbances: list = field(default_factory=list)
    #: The first this many disturbances were taken out of the record before fitting (:meth:`record_fitted`); the
    #: rest, found only in the final model's residual, are counted in ``noise``.
    n_removed: int = 0
    #: The sensor noise read in the record's holds (.colour), where it is the floor: larger than the white part.
    noise_holds: float | None = None
    #: The sensor noise the user gave (``sensor_noise``), where it is the floor: more than the record shows.
    noise_given: float | None = None
    #: The reading's quantisation step (m), where not fine against its noise: ``noise_white`` is then the
    #: quantisation error with the noise, read by local fits (:mod:`~hyst_model.effects.quantised`).
    noise_step: float | None = None

    def record_fitted(self, t: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The output the models were fitted to: ``y`` without the lines taken out (``y`` when none were)."""
        return without_lines(t, y, self.disturbances[:self.n_removed])

    def to_json(self) -> dict:
        return {
            "baseline": {"model": self.base, "rmse": self.baseline_rmse, "rmse_train": self.baseline_rmse_train},
            "noise_floor": self.noise,
            "noise_floor_white": self.noise if self.noise_white is None else self.noise_white,
            "disturbances": [dict(ln.to_json(), removed=i < self.n_removed) for i, ln in enumerate(self.disturbances)],
            "noise_floor_holds": self.noise_holds,
            "noise_floor_given": self.noise_given,
            "noise_floor_step": self.noise_step,
            "candidates": [{"effect": c.effect, "rmse": c.rmse, "improvement": c.improvement,
                            "significant": c.significant, "score": c.score, "t_stat": c.t_stat,
                            "rmse_without": c.rmse_without,
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
            "caution": self.caution,
            "undetermined": [x.to_json() for x in self.undetermined],
        }


@one_blas_thread
def diagnose(t, u, y, *, base: str = "mbw", effects: Sequence[str] | None = None, fitter=None,
             min_factor: float = 1.1, t_min: float = 3.0, noise_margin: float = 1.1,
             unexplained_factor: float = UNEXPLAINED_FACTOR,
             full_rate_top: int = 6, max_rungs: int = 3, progress: bool | Callable = False,
             config: dict | None = None, jobs: int | None = None, sensor_noise: float | None = None) -> Diagnosis:
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
        Baseline validation RMSE below ``noise_margin × noise floor`` → nothing is missing (and the ladder stops
        there). The same 1.1 as ``min_factor``: an error that close to the floor could not be cut significantly,
        and a larger one is left to the candidates' own test. The floor estimate itself is good to a few %
        (base/floor 0.97–1.03 on 32 generated records without an effect); with 1.25 here, effects 15–90× the
        noise that the base imitated on the record to within 10–25 % were never tested.
    unexplained_factor : float
        Final validation RMSE at or above this × the noise floor is described as unexplained; with no
        significant effect the verdict is then ``"unexplained"`` instead of ``"none"``.
    full_rate_top : int
        How many screened candidates get the full joint refit at each further rung of the ladder (at the first
        rung every candidate does). The default, 6, is every built-in effect: with the 2 best screened only, a
        candidate the screen (rung held fixed) undersold was never refitted (pairs both in the top two on
        generated seed 1: 29 % with 2, 47 % with all; the 60k-sample diagnose takes about twice as long).
    max_rungs : int
        Effects in the ladder at most.
    progress : bool or callable
        Print progress lines on stderr (or pass each line to a callable).
    config : dict, optional
        Effect configuration the user fixes (``{"dynamics.interp": "fft", "dynamics.structure": "feedback"}``):
        it overrides the data-derived settings, and an effect's variants that would change a fixed key are not
        tried.
    jobs : int, optional
        Threads fitting the candidates side by side (default: the processors available, at most 6). The result
        does not depend on it (:mod:`hyst_model.diagnose.parallel`).
    sensor_noise : float, optional
        The sensor's noise RMS (m) where the user knows it — from a record of the stage at rest, or the sensor's
        data sheet at the bandwidth recorded —, for noise that is not white on a record without holds (sines,
        sweeps, noise), where the record itself shows only the white part. The floor is the larger of it and
        what the record shows (the record cannot show less noise than there is).

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
    if sensor_noise is not None and not (math.isfinite(sensor_noise) and sensor_noise > 0):
        raise DataError(f"the sensor noise must be an RMS > 0 in metres, not {sensor_noise!r}")
    n = t.size
    need = int(math.ceil(max(MIN_TRAIN / (1 - SPLIT), MIN_VALID / SPLIT)))
    if n < need:
        raise FitError(f"too little data for validation: {n} samples; diagnose holds out "
                       f"{SPLIT:.0%} in {BLOCKS} blocks and needs at least {need} samples")
    val = validation_mask(n, u)
    train = ~val
    fit_ = fitter or default_fitter
    dt = sample_time(t)
    cfg = dict(_scales(u, y), dt=dt)
    fixed = dict(config or {})
    cfg.update(fixed)
    base_model = build_model(base, (), cfg)
    names = candidate_names(base_model, effects)
    cfg.update(effects_data_config(names, t, u, y, train))  # each effect's own settings from the data
    cfg.update(fixed)
    n_steps = 1 + 2 * len(names) + (full_rate_top + 1) * max_rungs
    say = progress if callable(progress) else _Progress(bool(progress), n_steps)

    say(f"fitting base model {base} on {n} samples ({train.sum()} train, {val.sum()} validation)")
    th_base = fit_(base_model, t, u, y, None)
    e_base = y - _simulate(base_model, th_base, t, u)
    lattice = lattice_step(y)              # a reading in coarse steps: the floor is local fits' (said)
    noise, step = record_floor_step(y, e_base, lattice)
    # A line in the output the input does not drive (mains pickup, .lines) is the sensor's, not the stage's: it is
    # taken out of the record before any model sees it, and the base refitted from where it ended — a mode left
    # to it rings at the line and is named (generated stages without an effect: dynamics on 4 of 12 with pickup).
    # One the base's larger error hid is looked for again in the final model's residual and counted in the floor.
    # The scales and each effect's data configuration stay those of the record as measured, as in hyst fit (one
    # path: both write the same model); a line moves a range or a centre by its amplitude, nanometres on microns.
    white = noise
    removed = disturbance_lines(t, u, e_base, white)
    if removed:
        y = without_lines(t, y, removed)
        th_base = fit_(base_model, t, u, y, th_base)
        e_base = y - _simulate(base_model, th_base, t, u)
        if lattice > 0.0:   # local fits read much of a line: the floor of the reading without them
            white, step = record_floor_step(y, e_base, lattice)
        say(f"took {lines_said(removed)} out of the output: the input does not drive "
            f"{'it' if len(removed) == 1 else 'them'} (mains pickup or an amplifier's ripple?)", step=False)
    # Noise that is not white (a sensor slower than the sampling) is read where the input is held still (.colour);
    # after the lines are out, which would count twice. The user's value where larger (.floor).
    floor, reading = read_floor(t, u, y, white, sensor_noise, step=step)
    noise = floor.value
    if step > 0.0:
        say(f"noise floor {fmt_len(white)}: the sensor reads in steps of {fmt_len(step)} (quantisation error and "
            "noise, read by local fits)", step=False)
    if floor.held is not None:
        say(f"noise floor {fmt_len(floor.held.rms)} from the record's {floor.held.holds} holds: the sensor noise is "
            f"not white ({floor.held.rms / white:.2g}× its white part)", step=False)
    if sensor_noise is not None and not floor.given_used:
        say(f"the record shows more noise ({fmt_len(noise)}) than the sensor noise given "
            f"({fmt_len(sensor_noise)}): the record's is the floor", step=False)
    s = Setup(t, u, y, val, dt, cfg, fixed, base, base_model, names, fit_, say, noise, th_base, e_base,
              min_factor, t_min, noise_margin, full_rate_top, max_rungs,
              default_jobs() if jobs is None else max(1, int(jobs)))
    say(f"base {base}: validation RMSE {fmt_len(s.base_val)}, noise floor {fmt_len(noise)}"
        + (" (at the noise floor)" if s.at_floor else ""), step=False)

    cands, carry, full = screen_all(s)                               # 1. each effect on the base held fixed
    ranked = refit_all(s, cands, carry, full)                        # 2. each refitted jointly, tested
    pair = joint_pair(s, cands, full, unexplained_factor)             # 2b. two only together, where none alone
    ladder, models, chosen = climb(s, ranked, cands, carry, full, pair)  # 3. the error ladder
    chosen = prune(s, ladder, models, chosen, cands)                 # 3b. and its backward step
    chosen, swapped = swap(s, ladder, models, chosen, cands, full)  # 3c. and its exchange step
    if swapped:
        chosen = prune(s, ladder, models, chosen, cands)
    if reconfigure(s, ladder, models, chosen, cands):                 # 3d. and each effect's configuration
        chosen = prune(s, ladder, models, chosen, cands)
    if ladder[-1].model != base:   # a line the base's larger error hid (a step record's transients)
        m_fin, th_fin = models[ladder[-1].model]
        more = disturbance_lines(t, u, y - _simulate(m_fin, th_fin, t, u), white)
        if more:   # counted in the floor, and the holds read again without them
            floor, reading = read_floor(t, u, y, white, sensor_noise, more, step)
            noise = s.noise = floor.value
            say(f"noise floor {fmt_len(noise)} with {lines_said(more)} in the final model's residual", step=False)
    ranked, missing, unexplained, expl = verdict(s, cands, ladder, models, chosen, unexplained_factor,
                                                 _explain)           # 4. the answer in words
    base_train = rmse(s.e_base[train])
    caution = base_caution(base, s.base_val, base_train, noise, u, unexplained_factor)
    said = False  # the caution is already in the explanation
    if missing == "unexplained":   # nothing named: is the held-out error evidence of anything missing at all?
        only = held_out_only(base, t, s.e_base, val, noise, noise_margin, unexplained_factor)
        if only is not None:
            missing, unexplained, expl = "none", None, only
            said = caution is None
            caution = caution or f"caution: {only}"
    if caution and not said:
        expl = f"{expl}; {caution}"
    und = undetermined(s, full, cands, list(chosen))                 # 5. what the record cannot tell apart
    if und:
        expl = f"{expl}; {sentence(und, noise, dt, (float(np.min(u)), float(np.max(u))))}"
    if removed:
        expl = (f"{expl}; {lines_said(removed)} in the output, which the input does not drive (mains pickup or an "
                "amplifier's ripple?), {} taken out of the record before fitting: every RMSE here is of the record "
                "without {}".format(*(("was", "it") if len(removed) == 1 else ("were", "them"))))
    said_floor = floor.words()
    if said_floor:
        expl = f"{expl}; {said_floor}"
    if (unexplained is not None and reading is None and sensor_noise is None and not floor.lines
            and ladder[-1].rmse < COLOUR_HINT * noise):
        expl = (f"{expl}; the floor is the white part of the sensor noise only: this record holds its input still "
                "too seldom to read the rest, and if the sensor's noise is not white (a sensor slower than the "
                "sampling) this remainder may be noise — record the stage at rest for a few seconds and give that "
                "record or its RMS (hyst diagnose --sensor-noise REST)")
    # what the user is handed: no stop where the record shows none (the same output on the record: .settle)
    models = {k: (m, settle(m, th, t, u)) for k, (m, th) in models.items()}
    return Diagnosis(base, s.base_val, base_train, noise, ranked, missing, ladder, expl, n, dt,
                     time.perf_counter() - t0, models, unexplained, caution, und, white, removed + list(floor.lines),
                     len(removed), floor.held.rms if floor.held is not None else None,
                     floor.value if floor.given_used else None, step if step > 0.0 else None)


def _explain(c: Candidate, base: str, base_val: float) -> str:
    onto = "+".join([base] + c.on_top_of)
    head = (f"adding {c.effect} to {onto} changes the validation RMSE from {fmt_len(base_val)} to "
            f"{fmt_len(c.rmse)} ({c.improvement:.2f}×)")
    tail = c.evidence.split("; adding ")[0]
    verdict = "significant" if c.significant else "not significant"
    return f"{head}, {verdict}; {tail}"
