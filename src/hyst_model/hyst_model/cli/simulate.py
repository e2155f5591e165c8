"""``hyst simulate --params P --input u.csv --out y.csv``: run a fitted model on an input record.

The input CSV has columns ``t,u`` (s, V; other names/units via ``--columns``/``--units``); the output CSV has
``t,u,y`` in SI units (y in m). The model starts from rest (the state reached holding ``u[0]``) and includes the
fitted output offset, so y is what the sensor would read. MBW's δ and rate terms are per sample: the input must be
sampled at the rate the model was identified at (``model.dt`` in the params file) unless ``--any-rate``.
"""
from __future__ import annotations

import argparse
import sys

from hyst_common.argtypes import nonneg_int

import numpy as np

from ..errors import DataError, FitError

__all__ = ["register", "run"]


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="simulate a fitted model on an input CSV",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", required=True, help="params file written by hyst fit")
    p.add_argument("--input", required=True, help="CSV with t,u (s, V)")
    p.add_argument("--out", required=True, help="CSV to write with t,u,y (s, V, m)")
    p.add_argument("--columns", help="input columns for t,u (default t,u)")
    p.add_argument("--units", help="units of those columns, e.g. ms,V")
    p.add_argument("--any-rate", action="store_true", help="allow a sample rate different from the fitted one")
    p.add_argument("--steady-periods", type=nonneg_int, default=0, metavar="N",
                   help="the input is one period of a periodic signal: run it N times from rest and write the "
                        "last period (steady state, as the Bouc-Wen benchmark scores its test); default 0 = once")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.add_argument("--effect-module", action="append", default=[], metavar="PATH",
                   help="Python file defining the Effect classes a params file uses (repeatable)")
    p.set_defaults(func=run)


def run(args) -> int:

    from ..io import read_params, write_csv
    from ..io.csvio import read_input_csv

    from ..io.outputs import check_output
    out = check_output(args.out, force=args.force, what="--out")
    from ..effects import load_effect_module
    for path in args.effect_module:
        load_effect_module(path)
    spec = read_params(args.params)
    model = spec.model()
    theta = spec.theta(model)
    t, u = read_input_csv(args.input, args.columns, args.units)
    if t.size == 0:
        raise DataError(f"{args.input}: no samples")
    if t.size > 1:  # the model is per sample: across a gap it would step on as if no time had passed
        d = np.diff(t)  # increasing: read_input_csv refuses any other
        med = float(np.median(d))
        bad = np.flatnonzero(d > 1.5 * med)
        if bad.size:
            k = int(bad[0])
            what = f"have a gap of {d[k]:.6g} s ({d[k] / med:.3g} sample periods)"
            raise DataError(f"{args.input}: time stamps {what} at row {k + 1} (t = {t[k]:.9g} then "
                            f"{t[k + 1]:.9g} s), {bad.size} place(s) in all: the model steps once per sample, so it "
                            "would run across as if no time had passed; give a regularly sampled input (hold the "
                            "voltage through a gap) or split the file")
    dt_fit = spec.config.get("dt")
    if not dt_fit and not args.any_rate:  # an old or hand-written file: say the check was not made
        print(f"hyst simulate: note: {args.params} gives no model.dt, so whether {args.input} is sampled at the "
              "model's rate was not checked (a per-sample model is only valid there)", file=sys.stderr)
    if t.size > 1 and dt_fit and not args.any_rate:
        dt = float(np.median(np.diff(t)))
        if abs(dt - float(dt_fit)) > 0.01 * float(dt_fit):
            raise DataError(f"{args.input} is sampled at {1 / dt:.6g} Hz but the model was identified at "
                            f"{1 / float(dt_fit):.6g} Hz; resample the input or pass --any-rate")
    if args.steady_periods < 0 or args.steady_periods > 1000:
        raise DataError("--steady-periods must be between 0 and 1000")
    from ..identify.input_range import output_note, range_note
    note = range_note(spec.fit, u)
    y = _run(model, theta, t, u, args.steady_periods)
    if not np.all(np.isfinite(y)):
        why = note or "input outside the range it was identified on?"
        raise FitError(f"the model diverges on {args.input} ({why})")
    for n in (note, output_note(spec.fit, y)):
        if n:
            print(f"hyst simulate: warning: {n}", file=sys.stderr)
    write_csv(out, {"t": t, "u": u, "y": y}, force=args.force)
    print(f"wrote {out} ({t.size} samples, y {y.min() * 1e6:.4g} .. {y.max() * 1e6:.4g} µm)", file=sys.stderr)
    return 0


def _run(model, theta, t: np.ndarray, u: np.ndarray, periods: int) -> np.ndarray:
    """Free run from rest; with ``periods`` ≥ 1, over that many repetitions of ``u``, returning the last one."""
    if periods <= 1:
        with np.errstate(all="ignore"):
            return np.asarray(model.simulate(theta, t, u), dtype=np.float64)
    n = t.size
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    tt = t[0] + np.arange(n * periods) * dt
    with np.errstate(all="ignore"):
        y = np.asarray(model.simulate(theta, tt, np.tile(u, periods)), dtype=np.float64)
    return y[-n:]
