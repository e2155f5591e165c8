"""``hyst excite --out u.csv``: write an open-loop identification excitation as a ``t,u`` CSV (s, V), no ROS.

The same generator ``hyst_excite_node`` plays (:mod:`hyst_control.excitation`), with the same defaults: steps with
holds, sines and triangles at several amplitudes (minor loops), a multisine, a sweep and, when asked for,
band-limited noise — inside the profile's range and slew limit, starting and ending at rest. What to do with it:

    hyst excite --profile pea --rate 2000 --parts steps,noise,sweep --out u.csv
    hyst excite --profile custom --v-min -10 --v-max 10 --out u.csv          # a stage outside the two profiles
    hyst simulate --params stage.yaml --input u.csv --out y.csv               # what the model expects
    hyst_excite_node --ros-args -p rate:=2000.0 -p file:=u.csv                # play it on the stage

``hyst diagnose`` advises this when a record cannot tell two effects apart (a mode below its resonance and a delay
on a few sines): steps, band-limited noise or a sweep over the range separate them.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from hyst_common.argtypes import nonneg_int
from hyst_common.errors import ConfigError as CommonConfigError
from hyst_common.profiles import CUSTOM_SWING_TIME, CUSTOM_V_MAX, GMA_LIMITS, PEA_LIMITS, custom_limits
from hyst_model.io.csvio import write_csv
from hyst_model.io.outputs import check_output

from .errors import ConfigError
from .excitation import (BAND_PARTS, DEFAULT_PARTS, DEFAULT_RATE, MAX_RATE, MIN_RATE, PARTS, PERIODIC_PARTS,
                         ExcitationSpec, build_excitation)

__all__ = ["register", "run", "spec_from_args", "unused_options"]


def _floats(text: str, what: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ConfigError(f"{what} {text!r}: a comma list of numbers is expected") from None


def register(subparsers) -> None:
    """Add the ``excite`` subcommand to the ``hyst`` dispatcher."""
    d = ExcitationSpec()
    p = subparsers.add_parser("excite", help="write an open-loop identification excitation (t,u CSV)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="CSV to write with t,u (s, V)")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.add_argument("--profile", choices=("pea", "gma", "custom"), default="pea",
                   help="limit defaults: pea (0-150 V, default), gma (+-5 V), or custom: another stage, whose "
                        f"range --v-min/--v-max must give (within +-{CUSTOM_V_MAX:g} V; slew default a full swing "
                        f"in {CUSTOM_SWING_TIME * 1e3:g} ms)")
    p.add_argument("--rate", type=float, default=DEFAULT_RATE, help=f"sample rate (Hz), default {DEFAULT_RATE:g}: "
                   "the stage's, since the MBW is identified per sample")
    p.add_argument("--v-min", type=float, default=None, help="lowest command (V), default the profile's")
    p.add_argument("--v-max", type=float, default=None, help="highest command (V), default the profile's")
    p.add_argument("--slew-max", type=float, default=None, help="slew limit (V/s), default the profile's")
    p.add_argument("--parts", default=",".join(DEFAULT_PARTS),
                   help=f"comma list of {', '.join(PARTS)}, played in this order (default {','.join(DEFAULT_PARTS)})")
    p.add_argument("--amplitudes", default=",".join(f"{a:g}" for a in d.amplitudes),
                   help="fractions of the range for sines/triangles; the largest for multisine, sweep, noise")
    p.add_argument("--frequency", type=float, default=d.frequency, help="sine/triangle frequency (Hz)")
    p.add_argument("--periods", type=int, default=d.periods, help="periods per sine/triangle amplitude")
    p.add_argument("--n-steps", type=int, default=d.n_steps, help="random step levels")
    p.add_argument("--hold", type=float, default=d.hold, help="step hold and pause between parts (s)")
    p.add_argument("--step-rise", type=float, default=d.step_rise, help="raised-cosine rise of each step (s)")
    p.add_argument("--f-lo", type=float, default=d.f_lo, help="multisine/sweep/noise lowest frequency (Hz)")
    p.add_argument("--f-hi", type=float, default=d.f_hi, help="multisine/sweep/noise highest frequency (Hz)")
    p.add_argument("--seconds", type=float, default=d.seconds, help="multisine, sweep and noise length (s)")
    p.add_argument("--seed", type=nonneg_int, default=d.seed, help="seed of step levels, multisine phases and noise")
    p.add_argument("--json", action="store_true", help="print one JSON object describing what was written")
    p.set_defaults(func=run)


def spec_from_args(args: argparse.Namespace) -> ExcitationSpec:
    """The excitation the arguments describe, inside the profile (a limit beyond it is refused, not clipped)."""
    if args.profile == "custom":
        if args.v_min is None or args.v_max is None:
            raise ConfigError("--profile custom needs --v-min and --v-max: the stage amplifier's range (V)")
        try:
            lim = custom_limits(args.v_min, args.v_max, args.slew_max)
        except CommonConfigError as err:
            raise ConfigError(f"--v-min/--v-max: {err}") from err
    else:
        lim = GMA_LIMITS if args.profile == "gma" else PEA_LIMITS
    v_min = lim.v_min if args.v_min is None else args.v_min
    v_max = lim.v_max if args.v_max is None else args.v_max
    if not (lim.v_min <= v_min and v_max <= lim.v_max):
        raise ConfigError(f"--v-min/--v-max {v_min:g}..{v_max:g} V leave the {args.profile} amplifier's range "
                          f"{lim.v_min:g}..{lim.v_max:g} V")
    slew = float(min(lim.slew_max, 1e9)) if args.slew_max is None else args.slew_max
    if not (math.isfinite(args.rate) and MIN_RATE <= args.rate <= MAX_RATE):  # what hyst_excite_node plays
        raise ConfigError(f"--rate must be in [{MIN_RATE:g}, {MAX_RATE:g}] Hz (hyst_excite_node's range), "
                          f"got {args.rate:g}")
    parts = tuple(x.strip() for x in args.parts.split(",") if x.strip())
    return ExcitationSpec(v_min=v_min, v_max=v_max, slew_max=slew, dt=1.0 / args.rate, parts=parts,
                          amplitudes=_floats(args.amplitudes, "--amplitudes"), frequency=args.frequency,
                          periods=args.periods, n_steps=args.n_steps, hold=args.hold, step_rise=args.step_rise,
                          f_lo=args.f_lo, f_hi=args.f_hi, seconds=args.seconds, seed=args.seed)


#: Options that only some parts use: (the parts, the option's attribute) — given for none of them, a note says so.
_PART_OPTIONS = ((BAND_PARTS, ("f_lo", "f_hi", "seconds")), (PERIODIC_PARTS, ("frequency", "periods")),
                 (("steps",), ("n_steps", "step_rise")), (PERIODIC_PARTS + BAND_PARTS, ("amplitudes",)))


def unused_options(spec: ExcitationSpec) -> list[str]:
    """Options set away from their defaults that none of ``spec.parts`` uses (a note, not an error: the same
    command line with other ``--parts`` uses them)."""
    d = ExcitationSpec()
    return [f"--{k.replace('_', '-')}" for parts, keys in _PART_OPTIONS if not set(spec.parts) & set(parts)
            for k in keys if getattr(spec, k) != getattr(d, k)]


def run(args: argparse.Namespace) -> int:
    out = check_output(args.out, force=args.force, what="--out")
    spec = spec_from_args(args)
    unused = unused_options(spec)
    if unused:
        print(f"hyst excite: note: {', '.join(unused)} not used by the parts {','.join(spec.parts)}", file=sys.stderr)
    ex = build_excitation(spec)
    write_csv(out, {"t": ex.t, "u": ex.u}, force=args.force)
    summary = {"out": str(out), "rate": 1.0 / spec.dt, "samples": int(ex.u.size), "seconds": ex.duration,
               "u_min": float(ex.u.min()), "u_max": float(ex.u.max()), "rest": spec.rest,
               "segments": [{"part": name, "t0": float(ex.t[a]), "t1": float(ex.t[b - 1])}
                            for name, a, b in ex.segments]}
    if args.json:
        print(json.dumps(summary))
    # the node checks the file against its own limits: name the same ones where they are not its defaults
    lims = "" if args.profile == "pea" and args.v_min is None and args.v_max is None else (
        f" -p profile:={args.profile} -p v_min:={float(spec.v_min)!r} -p v_max:={float(spec.v_max)!r}")
    print(f"wrote {out}: {', '.join(spec.parts)}, {ex.duration:.3f} s at {1 / spec.dt:g} Hz ({ex.u.size} samples), "
          f"{ex.u.min():.4g}..{ex.u.max():.4g} V; play it with: hyst_excite_node --ros-args "
          f"-p rate:={1 / spec.dt:g}{lims} -p file:={out}", file=sys.stderr)
    return 0
