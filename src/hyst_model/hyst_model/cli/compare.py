"""``hyst compare DATA --params P``: where does a fitted model fail on a measured record?

Runs the model of a params file in simulation (free-run) mode on the record's input and prints fit figures
overall, per input segment (holds, steps, sines by frequency), per branch (rising/falling input), per input
level and per frequency band, plus the residual tests of :mod:`hyst_model.diagnose.stats` (whiteness,
residual–input cross-correlation, higher-order tests) in plain words. ``--json`` prints one JSON object
instead; ``--report DIR`` writes PNG plots and an ``index.html`` (:func:`hyst_model.diagnose.report.write_report`).

Examples::

    hyst compare bags/run1 --params stage.yaml --report out/run1
    hyst compare piezo.csv --columns t_s,voltage_V,displacement_um --params piezo.yaml --json
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from hyst_common.argtypes import positive_int

import numpy as np

from ..diagnose.report import findings
from ..errors import DataError, HystError

__all__ = ["register", "run", "compare_record", "summary_text", "findings"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` subcommand."""
    p = subparsers.add_parser(
        "compare", help="compare a fitted model with measured data: fit figures, residual tests, report",
        description="Run the model of a params file on a record (bag or CSV) in simulation mode and show where "
                    "it fails: by time segment, input branch, input level and frequency band, with residual "
                    "whiteness / cross-correlation tests (99 %% bounds, as MATLAB resid) and higher-order "
                    "tests for even-order effects.")
    p.add_argument("data", metavar="DATA", help="rosbag2 directory / .mcap file (/stage/state) or CSV file")
    p.add_argument("--params", "-p", required=True, metavar="P", help="params file written by 'hyst fit'")
    p.add_argument("--report", metavar="DIR", help="write PNG plots and index.html into DIR")
    p.add_argument("--force", action="store_true",
                   help="write the report into DIR even if it holds files hyst did not write")
    p.add_argument("--json", action="store_true", help="print one JSON object with the figures")
    p.add_argument("--window", metavar="T0:T1",
                   help="score only samples with T0 <= t < T1 (s); the model still runs over the whole record")
    p.add_argument("--effect-module", action="append", default=[], metavar="PATH",
                   help="Python file with user effects the params file uses (repeatable)")
    p.add_argument("--any-rate", action="store_true",
                   help="compare a record sampled at another rate than the model was fitted at (as hyst simulate)")
    p.add_argument("--levels", type=positive_int, default=5, help="number of input-level bins (default 5, at most 100)")
    p.add_argument("--lags", type=positive_int, default=25, help="lags of the correlation tests (default 25)")
    from .fit import add_data_options
    add_data_options(p)  # --topic, --columns, --units, --gaps, --salvage, --resample: as fit and diagnose
    p.set_defaults(func=run)


def _window(text: str | None) -> tuple[float, float]:
    if not text:
        return -np.inf, np.inf
    a, sep, b = text.partition(":")
    try:
        if not sep:
            raise ValueError
        t0 = float(a) if a.strip() else -np.inf
        t1 = float(b) if b.strip() else np.inf
    except ValueError:
        raise DataError(f"--window must look like T0:T1 in seconds (got {text!r})") from None
    if not t1 > t0:
        raise DataError(f"--window {text!r} is empty")
    return t0, t1


#: Most input-level bins ``--levels`` takes.
MAX_LEVELS = 100


def compare_record(record, model, theta, *, n_levels: int = 5, max_lag: int = 25,
                   window: tuple[float, float] = (-np.inf, np.inf), diverges_why: str | None = None):
    """Model output and :class:`~hyst_model.diagnose.stats.CompareStats` of ``model`` at ``theta`` on ``record``.

    The model runs over the whole record (a hysteretic state depends on the input history) in simulation mode;
    only samples with ``window[0] <= t < window[1]`` are scored. Returns ``(scored_record, yhat, stats)``.
    ``diverges_why`` replaces the generic question in the divergence error (e.g. the input range note).

    Raises
    ------
    HystError
        The model produces non-finite output on this input (diverges), or the window holds too few samples.
    """
    from ..diagnose.stats import compare_stats
    try:
        yhat = np.asarray(model.simulate(np.asarray(theta, float), record.t, record.u), dtype=np.float64)
    except HystError:
        raise
    except (ValueError, FloatingPointError, ZeroDivisionError) as err:
        raise HystError(f"the model cannot be run on {record.source}: {err}") from err
    if yhat.shape != record.y.shape:
        raise HystError(f"model output has {yhat.size} samples for {record.y.size} inputs")
    m = (record.t >= window[0]) & (record.t < window[1])
    if m.sum() < 20:
        raise DataError(f"{record.source}: no samples in the window ({int(m.sum())} found, at least 20 needed)")
    rec = record.between(*window) if not m.all() else record
    yhat = yhat[m]
    if not np.all(np.isfinite(yhat)):
        k = int(np.flatnonzero(~np.isfinite(yhat))[0])
        why = diverges_why or "was it fitted on a comparable input range and sample rate?"
        raise HystError(f"the model diverges on this input (non-finite output from t={rec.t[k]:.4g} s); {why}")
    try:
        st = compare_stats(rec.t, rec.u, rec.y, yhat, n_levels=n_levels, max_lag=max_lag)
    except ValueError as err:
        raise DataError(f"{rec.source}: {err}") from err
    return rec, yhat, st


def _um(x: float) -> str:
    from ..effects.signals import fmt_len
    return fmt_len(x) if np.isfinite(x) else "n/a"


def _pct(x: float) -> str:
    return f"{x:6.1f} %" if np.isfinite(x) else "   n/a"


def summary_text(st, title: str = "") -> str:
    """The human-readable summary ``hyst compare`` prints."""
    o = st.overall
    lines = []
    if title:
        lines.append(title)
    q = st.extra.get("noise_step")
    lines.append(f"samples {o.n} at {st.fs:.6g} Hz ({o.n / st.fs:.4g} s); output noise ≈ {_um(st.noise_sigma)}"
                 + (f" (read in steps of {_um(q)}: quantisation error and noise)" if q else ""))
    lines.append(f"overall  RMSE {_um(o.rmse)}  NRMSE {100 * o.nrmse:.2f} %  fit {_pct(o.fit_percent)}  "
                 f"bias {_um(o.bias)}  max {_um(o.max_abs)}")
    lines.append("by segment:")
    for s in st.segments:
        lines.append(f"  {s.label:<18} {s.t0:9.4g}–{s.t1:<9.4g} s  RMSE {_um(s.fit.rmse):>10}  "
                     f"fit {_pct(s.fit.fit_percent)}")
    lines.append("by branch:")
    for k, f in st.branches.items():
        if f.n:
            lines.append(f"  {k:<8} n={f.n:<7} RMSE {_um(f.rmse):>10}  bias {_um(f.bias):>10}")
    lines.append("by input level:")
    for lo, hi, f in st.levels:
        lines.append(f"  [{lo:9.4g}, {hi:9.4g}]  n={f.n:<7} RMSE {_um(f.rmse):>10}  bias {_um(f.bias):>10}")
    lines.append("by frequency band:")
    for b in st.bands:
        lines.append(f"  {b.f_lo:9.4g}–{b.f_hi:<9.4g} Hz  residual {_um(b.rmse):>10}  measured {_um(b.y_rms):>10}")
    lag_s = st.lag_step / st.fs
    lines.append(f"residual tests (99 % bounds, {len(st.auto.lags) - 1} lags of {lag_s * 1e3:.3g} ms):")
    for c in [st.auto, st.cross, *st.higher.values()]:
        mark = "FAIL" if c.significant else "ok  "
        lines.append(f"  {mark} {c.name:<8} max |r| {c.max_abs:.3f} at {c.lag_at_max / st.fs * 1e3:8.3g} ms  "
                     f"bound ±{c.bound:.3f}  outside {100 * c.frac_outside:.0f} % of lags")
    f = findings(st)
    if f:
        lines.append("findings:")
        lines.extend(f"  - {x}" for x in f)
    return "\n".join(lines)


def _load(args) -> tuple[Any, Any, Any, np.ndarray]:
    from ..effects import load_effect_module
    from ..io import read_params
    for m in args.effect_module:
        load_effect_module(m)
    spec = read_params(args.params)
    model = spec.model()
    theta = spec.theta(model)
    from .fit import load_checked
    rec = load_checked(args)
    return spec, rec, model, theta


def run(args: argparse.Namespace) -> int:
    """Entry point of ``hyst compare``; returns the exit code."""
    if args.levels < 1 or args.lags < 1:
        raise DataError("--levels and --lags must be at least 1")
    if args.levels > MAX_LEVELS:  # 100 000 bins printed 100 031 lines of empty bins, silently
        raise DataError(f"--levels {args.levels}: at most {MAX_LEVELS} input-level bins (one table line each)")
    window = _window(args.window)
    if args.report:  # judged before the work, as the writer will
        from ..diagnose.report import check_report_dir
        check_report_dir(args.report, args.force, "compare")
    spec, rec, model, theta = _load(args)
    notes = []
    dt_fit = spec.config.get("dt")
    if not dt_fit and not args.any_rate:
        notes.append(f"note: {args.params} gives no model.dt, so whether the record ({1 / rec.dt:.6g} Hz) is sampled "
                     "at the model's rate was not checked (a per-sample model is only valid there)")
    if isinstance(dt_fit, (int, float)) and dt_fit > 0 and abs(rec.dt / dt_fit - 1.0) > 0.02:
        if not args.any_rate:  # as hyst simulate: the per-sample model's error there is the rate's, not the model's
            raise DataError(f"{args.data} is sampled at {1 / rec.dt:.6g} Hz but the model was identified at "
                            f"{1 / dt_fit:.6g} Hz; per-sample models do not transfer across sample rates: refit "
                            "at this rate, or pass --any-rate to compare anyway")
        notes.append(f"note: the model was fitted at a {dt_fit * 1e3:.4g} ms sample period, this record has "
                     f"{rec.dt * 1e3:.4g} ms; per-sample models do not transfer across sample rates")
    from ..identify.input_range import output_note, range_note
    far = range_note(spec.fit, rec.u)
    if far:
        notes.append(f"note: {far}")
    rec, yhat, st = compare_record(rec, model, theta, n_levels=args.levels, max_lag=args.lags, window=window,
                                   diverges_why=far)
    off = output_note(spec.fit, yhat)
    if off:
        notes.append(f"note: {off}")
    report_dir = None
    if args.report:
        from ..diagnose.report import write_report
        report_dir = write_report(args.report, rec, yhat, st, force=args.force, kind="compare",
                                  title=f"hyst compare: {rec.source} vs {args.params}")
    if args.json:
        d = {"data": rec.source, "params": str(args.params), "model": getattr(model, "name", "?"),
             **st.to_dict(), "findings": findings(st), "notes": notes,
             "data_notes": list(rec.meta.get("regularised", [])),
             "report": str(report_dir / "index.html") if report_dir else None}
        print(json.dumps(_clean(d), allow_nan=False))
    else:
        for n in notes:
            print(n, file=sys.stderr)
        print(summary_text(st, f"hyst compare: {rec.source} vs {args.params} (model {getattr(model, 'name', '?')})"))
        if report_dir:
            print(f"report: {report_dir / 'index.html'}")
    return 0


def _clean(o):
    """JSON-safe copy: numpy scalars to Python, NaN/inf to None (JSON has no NaN)."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return [_clean(v) for v in o.tolist()]
    if isinstance(o, (bool, np.bool_)):
        return bool(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    return o
