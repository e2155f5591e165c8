"""``hyst diagnose DATA``: which physical effect is the model missing?

Fits the base model, tests every effect of :data:`hyst_model.effects.EFFECTS` (plus those of ``--effect-module``
files) by its residual signature and by a refit with held-out validation, and prints the ranking, the evidence
in words, the error ladder and the verdict (see :mod:`hyst_model.diagnose.diagnose`). ``--json`` prints exactly
one JSON object; ``--report DIR`` writes the HTML report of :mod:`hyst_model.diagnose.report`.

Exit status: 0 when an effect is named or nothing is missing (``none``), 3 when the error is ``unexplained``
(at least 2× the noise floor and no library effect explains it; the JSON's ``unexplained`` says whether it is
the loop shape or something outside the library; below 5× with the training samples at the floor it is ``none``
with a ``caution``: the error lies only where the hold-out goes beyond training), 2 for bad input.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

from hyst_common.argtypes import positive_float, positive_int

__all__ = ["register", "run"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "diagnose", help="name the physical effect the model is missing (creep, delay, drift, ...)",
        description="Fit the base model, test each effect by its residual signature and a validated refit, "
                    "rank them and name the missing one ('none' when the residual is at the noise floor, "
                    "'unexplained' when it is ≥ 2× the noise floor and no library effect explains it).",
        epilog="exit status: 0 effect named or none missing; 3 unexplained; 2 bad input")
    p.add_argument("data", metavar="DATA", help="rosbag2 directory / .mcap file (/stage/state) or CSV file")
    p.add_argument("--base", default="mbw", choices=("mbw", "bw"), help="base model (default mbw)")
    p.add_argument("--effects", default=None, help="only test these effects (comma-separated; default all)")
    p.add_argument("--effect-module", action="append", default=[], metavar="PATH",
                   help="Python file defining extra Effect classes (repeatable)")
    p.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                   help="fix an effect's configuration, e.g. dynamics.interp=fft or dynamics.structure=feedback "
                        "(repeatable; its other variants are then not tried)")
    p.add_argument("--report", metavar="DIR", help="write an HTML report with plots into DIR")
    p.add_argument("--out", metavar="P", help="write the best model of the error ladder as a params file")
    p.add_argument("--admissible", action="store_true",
                   help="refit the model named (what --out saves) with Remark 4.1 and passive rate terms (psi >= 0) "
                        "when it lies outside them, as hyst fit --admissible: the model the controllers can also "
                        "run open loop; both validation figures are reported")
    p.add_argument("--force", action="store_true", help="allow --report/--out to replace existing output")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--quiet", action="store_true", help="no progress display on stderr")
    p.add_argument("--sensor-noise", default=None, metavar="M|REST",
                   help="the sensor's noise RMS in metres (e.g. 3e-9), or a record (CSV or bag) of the stage at rest "
                        "to read it from: the noise floor where it is more than the record shows — noise that is "
                        "not white, on a record without holds (steps with holds show it themselves)")
    p.add_argument("--jobs", type=positive_int, default=None, metavar="N",
                   help="threads fitting the candidates side by side (default: the processors, at most 6; "
                        "the result does not depend on it)")
    from .fit import add_data_options
    add_data_options(p)
    p.set_defaults(func=run)


def _clean(o):
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, bool):
        return o
    if isinstance(o, float) or hasattr(o, "dtype"):
        v = float(o)
        return v if math.isfinite(v) else None
    return o


def _text(d, source: str, adm=None) -> str:
    from ..effects.signals import fmt_len
    lines = [f"hyst diagnose: {source} ({d.n_samples} samples at {1.0 / d.dt:.6g} Hz, "
             f"diagnosed in {d.seconds:.1f} s)",
             f"baseline {d.base}: validation RMSE {fmt_len(d.baseline_rmse)} "
             f"(training {fmt_len(d.baseline_rmse_train)}); sensor noise floor ≈ {fmt_len(d.noise)}",
             "candidates, best first:"]
    for c in d.candidates:
        mark = "*" if c.significant else " "
        lines.append(f" {mark} {c.effect:<11} validation RMSE {fmt_len(c.rmse):>10}  {c.improvement:7.2f}×  "
                     f"residual test {c.score:.2f}")
        lines.append(f"      {c.evidence}")
    lines.append("error ladder: " + " → ".join(f"{r.model} {fmt_len(r.rmse)}" for r in d.ladder))
    lines.append(f"missing effect: {d.missing}"
                 + (f" ({d.unexplained.kind})" if d.missing == "unexplained" and d.unexplained else ""))
    lines.append(d.explanation)
    if d.missing not in ("none", "unexplained"):
        eff = ",".join(d.ladder[-1].effects)
        lines.append(f"next: hyst diagnose DATA --out params.yaml saves {d.ladder[-1].model} as fitted here "
                     f"(or refit it: hyst fit DATA --model {d.base} --effects {eff})")
    if adm is not None:
        lines.append(f"controllers ({d.ladder[-1].model}): {adm.controllers}")
        lines += [f"  {v}" for v in adm.violations + adm.at_bounds]
    return "\n".join(lines)


def sensor_noise_arg(text: str | None, quiet: bool = True) -> float | None:
    """``--sensor-noise``: an RMS in metres, or a record of the stage at rest to read it from
    (:func:`hyst_model.diagnose.colour.rest_noise`); a bad value is one clear :class:`DataError`."""
    if text is None:
        return None
    from ..errors import DataError
    try:
        return positive_float(text)
    except argparse.ArgumentTypeError as err:
        if not os.path.exists(text):
            raise DataError(f"--sensor-noise: {err} (an RMS in metres, or a record of the stage at rest)") from err
    from ..diagnose.colour import rest_noise
    from ..io import load_record
    rec = load_record(text)
    try:
        rms = rest_noise(rec.u, rec.y)
    except ValueError as err:
        raise DataError(f"--sensor-noise {text}: {err}") from err
    if not rms > 0:
        raise DataError(f"--sensor-noise {text}: the record at rest shows no noise at all")
    if not quiet:
        print(f"hyst diagnose: sensor noise {rms * 1e9:.3g} nm RMS read from {text} ({len(rec.y)} samples at rest, "
              "a quadratic trend removed)", file=sys.stderr)
    return rms


def run(args: argparse.Namespace) -> int:
    """Entry point; returns the exit code (errors raise HystError → exit 2 in the dispatcher)."""
    from ..io.outputs import check_output
    if getattr(args, "out", None):  # refuse now, not after minutes of fitting
        check_output(args.out, force=args.force, what="--out")
    if getattr(args, "report", None):
        if os.path.isdir(args.report):  # judged now as the writer will, not after the whole diagnosis
            from ..diagnose.report import check_report_dir
            check_report_dir(args.report, args.force, "diagnose")
        else:
            check_output(args.report, force=args.force, what="--report", directory=True)
    from ..diagnose.diagnose import diagnose
    from ..effects import load_effect_module
    from ..errors import EffectError, HystError
    if args.jobs is not None and args.jobs < 1:
        raise HystError(f"--jobs must be at least 1, not {args.jobs}")
    from .fit import load_checked

    for path in args.effect_module:
        load_effect_module(path)
    from .fit import parse_effects
    names = parse_effects(args.effects) if args.effects is not None else None
    if names and len(set(names)) != len(names):
        raise EffectError("--effects lists an effect twice")
    from ..effects import EFFECTS
    from .fit import parse_config
    user_cfg = parse_config(args.config, names or sorted(EFFECTS))
    sensor_noise = sensor_noise_arg(args.sensor_noise, args.quiet)
    rec = load_checked(args)
    d = diagnose(rec.t, rec.u, rec.y, base=args.base, effects=names, progress=not args.quiet, config=user_cfg,
                 jobs=args.jobs, sensor_noise=sensor_noise)
    # The model diagnose hands on is checked as hyst fit checks its fit (one path): Remark 4.1 and parameters on
    # their bounds, in the text, the JSON and the params file's provenance.
    from ..identify.admissible import check_admissible
    best = d.ladder[-1]
    fm, fth = d.models[best.model]
    y = d.record_fitted(rec.t, rec.y)   # without the lines the input does not drive, where diagnose found some
    from ..diagnose.lines import removal_note
    # what was done to the record, as hyst fit says it
    notes = list(rec.meta.get("regularised", [])) + removal_note(d.disturbances[:d.n_removed])
    adm = check_admissible(fm, fth, record=(rec.t, rec.u, y))
    rmse_v, rmse_t, constrained = best.rmse, best.rmse_train, None
    if args.admissible:
        from ..diagnose.refit import validation_mask
        from ..effects.signals import fmt_len
        from ..identify.admissible import constrain, constrained_summary, require_remark
        require_remark(adm, best.model)
        con = constrain(fm, rec.t, rec.u, y, fth, validation_mask(len(rec.t), rec.u))  # diagnose's own split
        if con is not None:
            constrained = constrained_summary(best.rmse, adm.violations, con.rmse)
            fth, rmse_v, rmse_t = con.theta, con.rmse, con.rmse_train
            d.models[best.model] = (fm, fth)
            adm = check_admissible(fm, fth, record=(rec.t, rec.u, y))
            if not args.quiet:
                print(f"hyst diagnose: {best.model} refitted with Remark 4.1 and passive rate terms (ψ ≥ 0): "
                      f"validation RMSE {fmt_len(con.rmse)} (as diagnosed {fmt_len(best.rmse)}, outside them)",
                      file=sys.stderr)
    # The report first: it takes seconds to plot, and a Ctrl-C there must not leave a params file behind.
    report_path = None
    if args.report:
        try:
            from ..diagnose import report as _report
        except ImportError:
            print("hyst diagnose: note: the HTML report module is not available; no report written",
                  file=sys.stderr)
        else:
            from .compare import compare_record
            model, theta = d.models[d.base]
            rec2, yhat, st = compare_record(rec, model, theta)   # the record as measured: its lines show
            out = _report.write_report(args.report, rec2, yhat, st,
                                       ladder=[_clean(r.__dict__) for r in d.ladder],
                                       diagnosis=_clean(d.to_json()), force=args.force, kind="diagnose",
                                       title=f"hyst diagnose: {rec.source} (plots: base model {d.base})")
            report_path = str(out / "index.html")
    out_path = None
    if args.out:
        from ..io import spec_from_model, write_params
        model, theta = fm, fth
        from ..identify.input_range import identified_range
        from ..diagnose.diagnose import BLOCKS, SPLIT
        # the provenance hyst fit --out writes: the notes on the record, the hold-out, the samples
        prov = {"method": "diagnose", "rmse": rmse_v, "rmse_train": rmse_t, "data": str(args.data),
                "split": f"train on {1 - SPLIT:.0%} of the samples, validate on {SPLIT:.0%} in {BLOCKS} interleaved "
                         "blocks, free-run from rest at the record start",
                "seconds": round(d.seconds, 3), "samples": len(rec),
                **({"data_notes": "; ".join(notes)} if notes else {}),
                "controllers": adm.controllers, **identified_range(rec.u, rec.y)}
        if constrained:
            from ..identify.admissible import provenance
            prov["admissible"] = provenance(constrained["free_rmse"])
        out_path = str(write_params(args.out, spec_from_model(model, theta, fit=prov, dt=rec.dt), force=args.force))
    if args.json:
        obj = _clean(d.to_json())
        obj["data"] = rec.source
        obj["data_notes"] = notes
        obj["report"] = report_path
        obj["params_file"] = out_path
        obj["admissibility"] = _clean(adm.to_json())
        obj["constrained"] = _clean(constrained)
        print(json.dumps(obj, allow_nan=False))
    else:
        print(_text(d, rec.source, adm))
        if report_path:
            print(f"report: {report_path}")
        if out_path:
            print(f"params: {out_path} ({d.ladder[-1].model})")
    return 3 if d.missing == "unexplained" else 0
