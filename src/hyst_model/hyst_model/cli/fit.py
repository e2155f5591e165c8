"""``hyst fit DATA``: identify a hysteresis model from a bag or CSV file and write a params file.

Examples::

    hyst fit bags/run1                                   # rosbag2 directory, /stage/state, MBW, fast
    hyst fit run.mcap --method epso --seed 1 --out params.yaml
    hyst fit piezo.csv --columns t_s,voltage_V,displacement_um --units s,V,um --train 3.257:6.257 --json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hyst_common.argtypes import nonneg_int, positive_float, positive_int

from ..errors import DataError, EffectError, HystError, ParamsError
from ..spec import parse_effect_config as parse_config
from ..identify.methods import METHODS

if TYPE_CHECKING:
    from ..io.record import Record

__all__ = ["register", "run", "add_data_options", "load_checked", "parse_split", "parse_config"]


#: ``--resample`` makes at most this many times the record's samples, and at most this many samples: a typo
#: (1e9 Hz) allocated 45 GiB and ended in a MemoryError traceback.
RESAMPLE_MAX_FACTOR = 50
RESAMPLE_MAX_SAMPLES = 20_000_000


def add_data_options(p: argparse.ArgumentParser) -> None:
    """Options shared by commands that read a record (bag or CSV)."""
    p.add_argument("--topic", default="/stage/state", help="state topic in a bag (default /stage/state)")
    p.add_argument("--columns", help="CSV columns for t,u,y, e.g. t_s,voltage_V,displacement_um (default t,u,y)")
    p.add_argument("--units", help="units of those columns, e.g. s,V,um (default: from the name suffix, else SI)")
    p.add_argument("--gaps", choices=("auto", "bridge", "longest", "refuse", "error"), default="auto",
                   help="irregular time stamps: auto (default) collapses repeated stamps (lockstep runs), bridges "
                        "gaps of up to 10 missed periods (input held, as the DAC holds it) and keeps the regular "
                        "segment between longer ones whose input varies most; bridge: the same but a longer gap is "
                        "an error; longest: keep the longest regular segment; refuse (= error): stop on any "
                        "irregularity")
    p.add_argument("--salvage", action="store_true",
                   help="read an MCAP bag whose recorder was killed (no footer) up to its damaged end")
    p.add_argument("--resample", type=positive_float, metavar="HZ",
                   help="resample to this rate before fitting (MBW's δ and rate terms are per sample)")


def parse_split(train: str | None, val_fraction: float, how: str = "tail"):
    """``--train T0:T1`` → (t0, t1); otherwise the validation fraction (``how="tail"``) or ``("blocks", f)``."""
    if train:
        try:
            a, b = (float(x) for x in train.split(":"))
        except ValueError:
            raise DataError(f"--train needs T0:T1 in seconds, got {train!r}") from None
        if not b > a:
            raise DataError(f"--train end must be after its start ({train})")
        return (a, b)
    if how == "blocks" and val_fraction > 0:
        return ("blocks", val_fraction)
    return val_fraction


def load_checked(args) -> Record:
    """Read DATA per the data options and check it; returns a regular, finite record in SI units."""
    from ..io import load_record
    from ..io.record import Record
    rec = load_record(args.data, topic=args.topic, columns=args.columns, units=args.units,
                      salvage=getattr(args, "salvage", False))
    if rec.meta.get("salvaged"):
        print(f"hyst: note: {args.data} is damaged; salvaged {len(rec)} samples before the damage", file=sys.stderr)
    from ..io.regular import regularise
    rec, notes = regularise(rec, args.gaps)
    for note in notes:
        print(f"hyst: note: {args.data}: {note}", file=sys.stderr)
    rec.meta["regularised"] = notes
    rec.check()
    from ..io.plausible import plausibility
    units = rec.meta.get("units") or ("s", "V", "m")
    for warning in plausibility(rec.t, rec.u, rec.y, input_unit=str(units[1]),
                                units_given=getattr(args, "units", None) is not None):
        print(f"hyst: warning: {args.data}: {warning}", file=sys.stderr)
    if args.resample is not None:
        dt = 1.0 / args.resample
        n = int((rec.t[-1] - rec.t[0]) / dt) + 1
        if n > min(RESAMPLE_MAX_FACTOR * len(rec), RESAMPLE_MAX_SAMPLES):
            raise DataError(f"--resample {args.resample:g} Hz would make {n} samples of the record's {len(rec)}: "
                            f"at most {RESAMPLE_MAX_FACTOR}x as many and {RESAMPLE_MAX_SAMPLES:,} samples")
        t = np.arange(rec.t[0], rec.t[-1] + 0.5 * dt, dt)
        t = t[t <= rec.t[-1]]
        rec = Record(t, np.interp(t, rec.t, rec.u), np.interp(t, rec.t, rec.y), dict(rec.meta, resampled=args.resample))
        rec.check()
    return rec


def register(subparsers) -> None:
    p = subparsers.add_parser("fit", help="identify a hysteresis model from a bag or CSV",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="rosbag2 directory, .mcap file, or CSV")
    p.add_argument("--model", default="mbw", help="base model: mbw (default), bw, pi")
    p.add_argument("--effects", default=None,
                   help="comma-separated effects composed onto the base, e.g. creep,delay (default none)")
    p.add_argument("--method", choices=tuple(METHODS), default="fast", help="identifier (default fast)")
    p.add_argument("--seed", type=nonneg_int, default=None, help="random seed (EPSO)")
    p.add_argument("--iterations", type=positive_int, default=None, help="EPSO iterations (default 200)")
    p.add_argument("--train", metavar="T0:T1", help="train on T0 <= t < T1 (s), validate on t >= T1")
    p.add_argument("--split", choices=("blocks", "tail"), default="blocks",
                   help="hold out --val-fraction in 8 interleaved blocks (default; what hyst diagnose does) or "
                        "as the record's tail")
    p.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                   help="effect configuration, e.g. dynamics.structure=feedback or delay.side=output (repeatable; "
                        "hyst diagnose writes the ones it chose into its params file)")
    p.add_argument("--val-fraction", type=float, default=0.25,
                   help="hold out this fraction of the record for validation, in 8 interleaved blocks or as the "
                        "tail (--split; default 0.25; 0 = none)")
    p.add_argument("--admissible", action="store_true",
                   help="enforce the thesis's Remark 4.1 (alpha_i < -|psi_i|) so DPPC/DMRAC run their own law: a "
                        "free fit that violates it is refitted with the constraint (both RMSEs reported)")
    p.add_argument("--out", help="write the params file here (ROS 2 parameters YAML)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--effect-module", action="append", default=[], metavar="PATH",
                   help="Python file defining extra Effect classes for --effects (repeatable)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_data_options(p)
    p.set_defaults(func=run)


def parse_effects(text: str | None) -> list[str]:
    """``--effects A,B`` as a list; None (not given) is no effects. An empty name (``""``, ``a,,b``, ``,``) is
    refused: it used to mean "no effects" to fit and "every effect" to diagnose, silently."""
    if text is None:
        return []
    names = [e.strip() for e in text.split(",")]
    if not all(names):
        raise ParamsError(f"--effects {text!r} has an empty name; list effects separated by commas, or leave the "
                          "option out")
    return names


def run(args) -> int:
    from ..io.outputs import check_output
    if args.out:  # fail before the imports and a long fit, not after them
        check_output(args.out, force=args.force, what="--out")
    from ..identify import fit
    from ..io import spec_from_model, write_params
    from ..models import BASE_MODELS, data_config
    from ..spec import build_model

    out = Path(args.out) if args.out else None
    if args.model not in BASE_MODELS:
        raise ParamsError(f"unknown model {args.model!r}; choose one of {', '.join(sorted(BASE_MODELS))}")
    from ..effects import load_effect_module
    for path in args.effect_module:
        load_effect_module(path)
    effects = parse_effects(args.effects)
    _check_options(args)
    split = parse_split(args.train, args.val_fraction, args.split)
    user_cfg = parse_config(args.config, effects)
    rec = load_checked(args)
    if isinstance(split, tuple) and split[0] == "blocks":
        from ..identify import block_mask
        from ..diagnose.diagnose import BLOCKS
        split = block_mask(len(rec), float(split[1]), BLOCKS, rec.u)  # the same hold-out as hyst diagnose
    config = data_config(rec.u, rec.y)
    config["dt"] = rec.dt
    if args.model in ("mbw", "bw"):
        # each effect's own settings from the scored samples, as hyst diagnose does (e.g. the drift knots' span)
        from ..spec import effect_settings
        config.update(effect_settings(effects, rec.t, rec.u, rec.y, split))
    config.update(user_cfg)
    try:
        model = build_model(args.model, effects, config)
    except (EffectError, ValueError) as err:
        raise DataError(f"--effects/--config: {err}") from err
    options = {}
    if args.iterations is not None:
        if args.method != "epso":
            raise HystError("--iterations applies to --method epso only")
        options["iterations"] = args.iterations
    if args.seed is None and METHODS[args.method].seeded:  # drawn, then said and kept: a fit can be repeated
        import secrets
        args.seed = secrets.randbelow(2 ** 31)
        if not args.quiet:
            print(f"hyst fit: {args.method} seed {args.seed} (--seed {args.seed} repeats this fit)", file=sys.stderr)
    res = fit(model, rec.t, rec.u, rec.y, method=args.method, seed=args.seed, split=split,
              progress=not args.quiet, **options)
    from ..diagnose.lines import removal_note, said
    res, y, lines = _without_lines(model, rec, res, split)
    if lines and not args.quiet:
        print(f"hyst fit: {said(lines)} in the output, which the input does not drive (mains pickup or an "
              "amplifier's ripple?), taken out of the record and the model refitted from its fit (as hyst diagnose "
              "does)", file=sys.stderr)
    notes = list(rec.meta.get("regularised", [])) + removal_note(lines)
    method = res.method if lines else args.method   # the refit's name says it was finished without the lines
    from ..effects.settle import settle_result
    from ..identify.admissible import check_admissible
    res = settle_result(model, res, rec.t, rec.u)  # no stop where the record shows none (effects.settle)
    adm = check_admissible(model, res.theta, record=(rec.t, rec.u, y))
    constrained = None
    if args.admissible:
        from ..identify.admissible import constrain, constrained_summary, require_remark
        require_remark(adm, args.model)
        con = constrain(model, rec.t, rec.u, y, res.theta, split)
        if con is not None:
            free, res = res, settle_result(model, con, rec.t, rec.u)
            constrained = constrained_summary(free.rmse, adm.violations, res.rmse)
            adm = check_admissible(model, res.theta, record=(rec.t, rec.u, y))
            if not args.quiet:
                print(f"hyst fit: Remark 4.1 and passive rate terms (ψ ≥ 0) enforced: validation RMSE "
                      f"{res.rmse * 1e9:.2f} nm (free fit {free.rmse * 1e9:.2f} nm, outside them)", file=sys.stderr)
    if not adm.clean and not args.json:
        for line in adm.violations + [f"{b}" for b in adm.at_bounds] + ([adm.divergence] if adm.divergence else []):
            print(f"hyst fit: warning: {line}", file=sys.stderr)
    if out is not None:
        prov = {"method": method, "rmse": res.rmse, "rmse_train": res.rmse_train, "data": str(args.data),
                "split": res.split, "seconds": round(res.seconds, 3), "samples": len(rec)}
        if notes:
            prov["data_notes"] = "; ".join(notes)
        if args.seed is not None:
            prov["seed"] = args.seed
        prov["controllers"] = adm.controllers
        from ..identify.input_range import identified_range
        prov.update(identified_range(rec.u, rec.y))
        if constrained:
            from ..identify.admissible import provenance
            prov["admissible"] = provenance(constrained["free_rmse"])
        write_params(out, spec_from_model(model, res.theta, fit=prov, dt=rec.dt), force=args.force)
    if args.json:
        obj = {"model": args.model, "effects": effects, "method": method, "rmse": res.rmse,
               "rmse_train": res.rmse_train, "seconds": res.seconds, "params": res.params,
               "n_evaluations": res.n_evaluations, "split": res.split, "samples": len(rec), "dt": rec.dt,
               "data": str(args.data), "out": str(out) if out else None,
               "data_notes": notes, "admissibility": adm.to_json(),
               "disturbances": [dict(ln.to_json(), removed=True) for ln in lines],
               "constrained": constrained}
        print(json.dumps(obj))
    else:
        print(_table(res, rec, out, adm))
    return 0


def _without_lines(model, rec: Record, res, split):
    """The fit on the record without the lines its residual shows that the input does not drive (mains pickup:
    :mod:`hyst_model.diagnose.lines`, found and taken out as ``hyst diagnose`` does, then refitted from ``res`` by
    its least squares); ``(res, y, lines)`` — ``res``, the record's own output and ``[]`` when there are none."""
    from dataclasses import replace

    from ..diagnose.lines import disturbance_lines, without_lines
    from ..effects.signals import record_floor
    from ..identify import fit
    with np.errstate(all="ignore"):
        e = rec.y - np.asarray(model.simulate(res.theta, rec.t, rec.u), dtype=np.float64)
    if not np.all(np.isfinite(e)):
        return res, rec.y, []
    lines = disturbance_lines(rec.t, rec.u, e, record_floor(rec.y, e))
    if not lines:
        return res, rec.y, []
    y = without_lines(rec.t, rec.y, lines)
    refit = fit(model, rec.t, rec.u, y, method="fast", split=split, theta0=res.theta, max_nfev=80)
    # the fit is the user's method's, finished on the cleaned record: its name, time and work add up
    refit = replace(refit, method=f"{res.method} (refitted without the lines)",
                    seconds=res.seconds + refit.seconds, n_evaluations=res.n_evaluations + refit.n_evaluations)
    return refit, y, lines


def _check_options(args) -> None:
    """Options that would be silently ignored are refused, as ``--iterations`` without EPSO always was."""
    if not 0.0 <= args.val_fraction < 1.0:
        raise DataError(f"--val-fraction must be in [0, 1) (0 = no hold-out), got {args.val_fraction:g}")
    if args.train and (args.split != "blocks" or args.val_fraction != 0.25):
        raise DataError("--train T0:T1 sets the split itself (train on T0..T1, validate after T1); drop --split "
                        "and --val-fraction")
    if args.seed is not None and not METHODS[args.method].seeded:
        raise DataError(f"--seed applies to --method epso only ({args.method} is deterministic)")


def _table(res, rec, out, adm) -> str:
    lines = [f"model {res.model}  method {res.method}  {len(rec)} samples at {1.0 / rec.dt:.6g} Hz  "
             f"{res.seconds:.2f} s  {res.n_evaluations} evaluations",
             (f"RMSE validation {res.rmse * 1e9:.2f} nm   training {res.rmse_train * 1e9:.2f} nm" if res.validated
              else f"RMSE training {res.rmse_train * 1e9:.2f} nm   (no validation samples: nothing held out)"),
             f"split: {res.split}", "", f"{'parameter':<16}{'value':>16}"]
    lines += [f"{k:<16}{v:>16.8g}" for k, v in res.params.items()]
    lines += ["", f"controllers: {adm.controllers}"]
    lines += [f"  Remark 4.1 violated: {v}" for v in adm.violations]
    lines += [f"  {b}" for b in adm.at_bounds]
    if out:
        lines += ["", f"wrote {out}"]
    return "\n".join(lines)
