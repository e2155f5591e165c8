"""``hyst track``: in-process closed loop on the default simulated stage (no ROS), tracking metrics in SI.

Example::

    hyst track --algorithm dppc --reference sine:10 --seconds 2 --rate 2000 --json
    hyst track --algorithm pid --resonance 350:0.04          # a stage resonance; gains checked and derated
    hyst track --params stage.yaml --scenario hidden_creep --reference c1     # the identified model, compensated

``--params`` runs the controller with the model of a params file — its base MBW and, unless ``--no-effects``, its
effects as compensation (:mod:`hyst_control.compensation`); ``--scenario`` makes the simulated stage a hidden-effect
scenario (a file, or the name of one shipped with hyst_sim, e.g. ``hidden_creep``).

``--stage`` says which stage is simulated: ``embedded`` (the PEA stage, 0–150 V), or ``params`` — the params
file's own stage: its base MBW, scales and ``dt`` as the truth, driven over the input range it was identified on
(``fit.u_min``..``fit.u_max``, or ``--v-min``/``--v-max``), slew limit a full swing in 1 ms. The default ``auto`` is
``embedded`` only when the file's identified range is the PEA's (inside 0–150 V, from its lowest to its highest
tenth, as a fit of the embedded stage is) or it records none (said), else ``params`` (a GMA's ±5 V, a ±10 V or a
20–120 V stage: the PEA stage would be driven where that model knows nothing). On the params stage the commands
are limited to its range, the divergence check uses it, and the reference is placed on its stroke
(:func:`hyst_control.reference.parse_reference` ``stroke``). Whatever the stage, commands beyond the range the
controller's model was identified on are reported (:func:`hyst_model.identify.input_range.range_note`).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys

from pathlib import Path

from hyst_control.compensation import Compensation, from_params
from hyst_control.controller_settings import model_divergence
from hyst_control.controllers import ALGORITHMS, CONTROLLERS, make_controller, make_supervised, mismatched
from hyst_common.argtypes import nonneg_int
from hyst_common.errors import ConfigError as CommonConfigError
from hyst_common.limits import CommandLimits
from hyst_common.profiles import PEA_LIMITS, custom_base, custom_limits, same_rate
from hyst_control.errors import ConfigError
from hyst_control.pid import gains_for
from hyst_control.reference import parse_reference
from hyst_control.stability import Resonance, guard, identified_resonance
from hyst_model.core import pea_default
from hyst_model.errors import HystError
from hyst_model.identify.input_range import range_note, stored_range
from hyst_model.io.params_file import read_params
from hyst_sim.errors import SimError
from hyst_sim.plant import Plant, PlantConfig
from hyst_sim.scenario import scenario_dir
from hyst_sim.truth_effects import Dynamics

from .loop import SimPlant, default_plant, run_closed_loop

__all__ = ["register", "run", "AT_END_SHARE"]

#: Share of a run's commands on the range's ends beyond which the reference is said to leave the stage's reach.
AT_END_SHARE = 0.01


def register(subparsers) -> None:
    """Add the ``track`` subcommand to the ``hyst`` dispatcher."""
    p = subparsers.add_parser(
        "track", help="closed loop on the simulated stage (no ROS): RMSE/MAE of a controller",
        description="Run a controller against a simulated stage (default the embedded PEA: 2 nm noise and "
                    "quantisation) "
                    "tracking a reference; print RMSE and MAE (in µm on the line, in metres with --json).")
    p.add_argument("--algorithm", choices=ALGORITHMS, default="dppc")
    p.add_argument("--reference", default="sine:10",
                   help="step, ramp, step+ramp, sine:F[:A_um], c1, c2, c3, case3 (default sine:10)")
    p.add_argument("--seconds", type=float, default=1.0, help="length of the run (s), default 1")
    p.add_argument("--rate", type=float, default=None,
                   help="loop rate (Hz), default 2000 (thesis), or the params file's 1/dt")
    p.add_argument("--mismatch", type=float, default=0.0,
                   help="relative model error of the controller's model, e.g. 0.2 (default 0)")
    p.add_argument("--initial", default="model", help="DMRAC initial estimates: model, cs0, cs1, cs2, cs3")
    p.add_argument("--thesis-rate", action="store_true",
                   help="DPPC/DMRAC: invert μ with the reference rate r_u (4.3)/(5.4) instead of the exact input "
                        "rate (DMRAC's adaptation keeps the applied input's rate: hyst_control.dmrac)")
    p.add_argument("--gain", action="append", default=[], metavar="NAME=VALUE",
                   help="set one gain of the algorithm (repeatable), e.g. --gain kappa1=0.5 --gain a_m=0.3; names "
                        "as the controller node's <algorithm>.<name> parameters")
    p.add_argument("--resonance", default="", metavar="FN[:ZETA]",
                   help="give the simulated stage a resonance after the hysteresis (Hz, damping ratio, default "
                        "0.05) and tell the controller, as an identified dynamics effect would: its gains are "
                        "checked against it (hyst_control.stability)")
    p.add_argument("--stability", choices=("derate", "warn", "refuse"), default="derate",
                   help="gains unstable against --resonance: derate them (default), warn and run them, or refuse")
    p.add_argument("--notch", action=argparse.BooleanOptionalAction, default=True,
                   help="pid under --stability derate: also try a notch on the command at the resonance and run it "
                        "when it keeps more gain (default; the node's stability.notch)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="sensor noise seed")
    p.add_argument("--params", default=None, metavar="P.yaml",
                   help="controller model from this params file (hyst fit / hyst diagnose --out); default: the "
                        "embedded stage model. Its effects are compensated unless --no-effects")
    p.add_argument("--no-effects", action="store_true", help="with --params: use its base MBW only")
    p.add_argument("--scenario", default=None, metavar="S.yaml",
                   help="simulated stage: a hidden-effect scenario file or a shipped name (hidden_creep, ...); "
                        "default: the embedded stage")
    p.add_argument("--stage", choices=("auto", "embedded", "params"), default="auto",
                   help="simulated stage: embedded (the PEA, 0-150 V), params (the --params file's own model, over "
                        "its identified input range) or auto (default): embedded when that range is the PEA's "
                        "(inside 0-150 V, from its lowest to its highest tenth) or none is recorded, else params")
    p.add_argument("--v-min", type=float, default=None,
                   help="--stage params: lowest command (V), default the file's identified fit.u_min")
    p.add_argument("--v-max", type=float, default=None,
                   help="--stage params: highest command (V), default the file's identified fit.u_max")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


#: How a yes/no gain may be written on the command line.
_BOOL = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


def _gains(args: argparse.Namespace, classes: dict, base=None):
    """The algorithm's gains with ``--gain`` overrides and ``--thesis-rate`` applied over ``base`` (default the
    law's defaults); None = the law's defaults unchanged."""
    cls = classes.get(args.algorithm)
    if cls is None:
        if args.gain:
            raise ConfigError(f"{args.algorithm} has no gains to set")
        return None
    kw: dict = {}
    names = {f.name: f.type for f in dataclasses.fields(cls)}
    for item in args.gain:
        name, _, value = item.partition("=")
        if name not in names:
            raise ConfigError(f"--gain {item!r}: {args.algorithm} gains are {', '.join(names)}")
        if name in kw:  # the last one won silently (hyst fit refuses a repeated --config alike)
            raise ConfigError(f"--gain {name} given twice; give each gain once")
        if names[name] in (bool, "bool"):
            flag = _BOOL.get(value.strip().lower())
            if flag is None:  # "on", "2", "ture" were read as false, silently
                raise ConfigError(f"--gain {item!r}: true or false is expected")
            kw[name] = flag
            continue
        try:
            kw[name] = float(value)
        except ValueError:
            raise ConfigError(f"--gain {item!r}: a number is expected") from None
    if args.thesis_rate and "exact_rate" in names:
        if kw.get("exact_rate") is True:
            raise ConfigError("--thesis-rate and --gain exact_rate=true contradict each other; give one")
        kw["exact_rate"] = False
    if base is not None:
        return dataclasses.replace(base, **kw)
    return cls(**kw) if kw else None


def _read_params(path: str):
    """The params file as a :class:`hyst_model.io.params_file.ParamsSpec` (read once per run)."""
    try:
        return read_params(path)
    except HystError as err:
        raise ConfigError(str(err)) from err


def _params_model(spec, path: str, rate: float):
    """Base MBW and compensation of a params file; its ``dt`` must match the loop rate."""
    mdt = spec.config.get("dt")
    if not mdt:
        print(f"hyst track: note: {path} gives no model.dt, so whether its model was identified at the loop's "
              f"{rate:g} Hz was not checked (the MBW recursion is per sample)", file=sys.stderr)
    if mdt and not same_rate(float(mdt), rate):
        raise ConfigError(f"{path} was identified at dt = {float(mdt):g} s: run with --rate {1.0 / float(mdt):g} "
                          "(the MBW recursion is per sample)")
    model, comp = from_params(spec, 1.0 / rate)
    return model, comp if comp.used or comp.unused else Compensation()


def _which_stage(args: argparse.Namespace, spec) -> str:
    """``embedded`` or ``params``: ``--stage``, with ``auto`` resolved from the params file's identified range."""
    if args.stage == "embedded" or (args.stage == "auto" and spec is None):
        if args.v_min is not None or args.v_max is not None:
            raise ConfigError("--v-min/--v-max set the range of --stage params; the embedded stage is 0-150 V")
        return "embedded"
    if spec is None:
        raise ConfigError("--stage params needs --params (the stage's model)")
    if args.stage == "params" or args.v_min is not None or args.v_max is not None:
        return "params"
    rng = stored_range(spec.fit, "u")
    if rng is None:  # nothing says it is another stage (said after the run, since it may be)
        return "embedded"
    return "embedded" if _pea_range(*rng) else "params"


def _pea_range(lo: float, hi: float) -> bool:
    """True when an identified input range is the PEA's: inside 0-150 V, from its lowest to its highest tenth
    (as a fit of the embedded stage on its excitation is); a 20-120 V stage is another stage."""
    span = PEA_LIMITS.v_max - PEA_LIMITS.v_min
    return (PEA_LIMITS.v_min <= lo <= PEA_LIMITS.v_min + 0.1 * span
            and PEA_LIMITS.v_max - 0.1 * span <= hi <= PEA_LIMITS.v_max)


def _stage_limits(args: argparse.Namespace, spec, path: str) -> CommandLimits:
    """The params stage's command limits: ``--v-min``/``--v-max``, else the range the file was identified on."""
    rng = stored_range(spec.fit, "u")
    lo = args.v_min if args.v_min is not None else (rng[0] if rng else None)
    hi = args.v_max if args.v_max is not None else (rng[1] if rng else None)
    if lo is None or hi is None:
        raise ConfigError(f"{path} records no identified input range (fit.u_min, fit.u_max): give the stage's "
                          "--v-min and --v-max (V)")
    try:
        return custom_limits(lo, hi)
    except CommonConfigError as err:
        raise ConfigError(f"--stage params range: {err}") from err


def _params_stage(path: str, rate: float, seed: int, lim: CommandLimits) -> PlantConfig:
    """The params file's own stage (its base MBW as the truth, the sensor of the rig's stages) over ``lim``."""
    try:
        return PlantConfig.from_params_file(path, custom_base(lim.v_min, lim.v_max), rate, seed=seed,
                                            v_min=lim.v_min, v_max=lim.v_max, slew_max=lim.slew_max,
                                            v_init=lim.v_safe)
    except (SimError, ValueError) as err:
        raise ConfigError(f"--stage params: {err}") from err


def _plant(scenario: str, rate: float, seed: int, base: PlantConfig | None = None):
    """A stage (default the embedded one) with a hidden-effect scenario (a file, or a name shipped with hyst_sim)."""
    path = Path(scenario)
    if not path.exists():
        named = scenario_dir() / (scenario if scenario.endswith(".yaml") else scenario + ".yaml")
        if not named.exists():
            shipped = ", ".join(sorted(p.stem for p in scenario_dir().glob("*.yaml")))
            raise ConfigError(f"--scenario {scenario}: no such file, nor a shipped scenario ({shipped})")
        path = named
    try:
        cfg = PlantConfig.from_scenario(path, base=base or PlantConfig.for_profile("pea", rate=rate, seed=seed))
    except (SimError, ValueError) as err:
        raise ConfigError(f"--scenario {scenario}: {err}") from err
    return SimPlant(Plant(cfg))


def _resonance(text: str) -> tuple[float, float]:
    fn, _, zeta = text.partition(":")
    try:
        fn_v, zeta_v = float(fn), float(zeta) if zeta else 0.05
    except ValueError:
        raise ConfigError(f"--resonance {text!r}: use FN[:ZETA], e.g. 350:0.04") from None
    if not (1.0 <= fn_v <= 20000.0 and 0.001 <= zeta_v <= 2.0):
        raise ConfigError("--resonance needs 1 <= FN <= 20000 Hz and 0.001 <= ZETA <= 2")
    return fn_v, zeta_v


def _resonant(rate: float, seed: int, fn: float, zeta: float, base: PlantConfig | None = None):
    """A simulated stage (default the embedded one) with a ZOH-exact resonance after the hysteresis (hyst_sim's
    dynamics effect)."""
    cfg = base or PlantConfig.for_profile("pea", rate, seed=seed)
    return SimPlant(Plant(cfg.replace(effects=cfg.effects.with_effects(dynamics=Dynamics(strength=fn,
                                                                                          damping=zeta)))))


def run(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.seconds) and 0 < args.seconds <= 600):
        raise ConfigError("--seconds must be in (0, 600]")
    if args.initial != "model" and args.algorithm != "dmrac":  # ignored silently before, as --gain never was
        raise ConfigError(f"--initial sets DMRAC's initial estimates; --algorithm {args.algorithm} has none")
    if args.thesis_rate and args.algorithm not in ("dppc", "dmrac"):
        raise ConfigError(f"--thesis-rate applies to DPPC and DMRAC (their reference rate), not {args.algorithm}")
    if args.no_effects and not args.params:  # ignored silently before, as --initial never was
        raise ConfigError("--no-effects drops the effects of a --params model; without --params there are none")
    spec = _read_params(args.params) if args.params else None
    if spec is not None and args.no_effects:
        spec.effects = []
    if args.rate is None:
        mdt = spec.config.get("dt") if spec is not None else None
        args.rate = 1.0 / float(mdt) if mdt else 2000.0
    if not (math.isfinite(args.rate) and 10 <= args.rate <= 20000):
        raise ConfigError("--rate must be in [10, 20000] Hz")
    stage = _which_stage(args, spec)
    limits = _stage_limits(args, spec, args.params) if stage == "params" else PEA_LIMITS
    base_cfg = _params_stage(args.params, args.rate, args.seed, limits) if stage == "params" else None
    comp = None
    if spec is not None:
        model, comp = _params_model(spec, args.params, args.rate)
    else:
        model = pea_default()
    model = mismatched(model, args.mismatch) if args.mismatch else model
    # the PID's SI defaults are the PEA's: on another stage they start from its loop gain, --gain on top of that
    scaled = gains_for(model, limits.v_min, limits.v_max) if stage == "params" and args.algorithm == "pid" else None
    gains = _gains(args, {name: law.gains for name, law in CONTROLLERS.items() if law.gains is not None}, scaled)
    if args.scenario:
        plant = _plant(args.scenario, args.rate, args.seed, base_cfg)
    else:
        plant = SimPlant(Plant(base_cfg)) if base_cfg is not None else default_plant(args.rate, args.seed)
    # the documented references sit on the PEA's stroke; another stage gets them on its own
    ref = parse_reference(args.reference, stroke=plant.plant.stroke_range if stage == "params" else None)
    stab = None
    resonance = None
    if args.resonance:
        fn, zeta = _resonance(args.resonance)
        plant = _resonant(args.rate, args.seed, fn, zeta, plant.plant.config)
        resonance = Resonance(fn, zeta)
    elif spec is not None:  # an identified resonance: the gains are checked against it, as the node does
        resonance = identified_resonance(spec.effects, spec.values, comp, spec.config)
    if resonance is None and (args.stability != "derate" or not args.notch):
        print("hyst track: note: --stability and --notch act on a resonance (--resonance, or a dynamics effect of "
              "--params); there is none here, so they change nothing", file=sys.stderr)
    if resonance is not None:
        stab = guard(args.algorithm, gains if gains is not None or args.algorithm == "open_loop" else
                     make_controller(args.algorithm, model, 1.0 / args.rate).gains, model, 1.0 / args.rate,
                     resonance, args.stability, v_range=(limits.v_min, limits.v_max), notch=args.notch)
        gains = stab.gains
        if stab.warn:
            print(f"hyst track: warning: {stab.message}", file=sys.stderr)
    # a model that runs away within the stage's limits: refused where it runs open loop, said where it does not
    diverging = model_divergence(args.algorithm, model, comp, limits, 1.0 / args.rate)
    if diverging:
        print(f"hyst track: warning: {diverging}", file=sys.stderr)
    ctrl = make_supervised(args.algorithm, model, 1.0 / args.rate, limits, gains=gains, initial=args.initial,
                           compensation=comp, act=args.stability != "warn")
    res = run_closed_loop(ctrl, ref, args.seconds, plant=plant)
    out = res.summary()
    at_end = res.at_limits(limits.v_min, limits.v_max)
    out.update(at_range_end=at_end)
    if at_end > AT_END_SHARE:  # the error is then the stage's reach, not the law's
        print(f"hyst track: warning: the commands sat on the range's ends ({limits.v_min:g} or {limits.v_max:g} V) "
              f"for {at_end:.0%} of the run, where the error is the range's, not the tracking's: the reference "
              "leaves what the stage reaches within its range (at this speed, or a level beyond its stroke) or the "
              "law drives its command to the limits (ringing, windup; see any oscillation warning)", file=sys.stderr)
    beyond = range_note(spec.fit, res.u) if spec is not None else None  # the model extrapolates there
    if beyond:
        out.update(range_warning=beyond)
        print(f"hyst track: warning: the commands leave the controller model's range: {beyond}", file=sys.stderr)
    if ctrl.events:  # the oscillation watch derated the law (a mode the model does not know)
        out.update(oscillation=list(ctrl.events))
        if not args.json:
            for msg in ctrl.events:
                print(f"hyst track: warning: {msg}", file=sys.stderr)
    if stab is not None and stab.running is not None:
        out.update(stability=stab.message, spectral_radius=stab.running.spectral_radius,
                   derated={n: b for n, _, b in stab.derated})
    out.update(stage=stage, v_min=limits.v_min, v_max=limits.v_max, reference=args.reference,
               reference_offset=ref.offset, reference_amplitude=ref.amplitude, mismatch=args.mismatch,
               units="m, V", params=args.params,
               scenario=args.scenario, compensated=comp.compensated(args.algorithm) if comp else [],
               not_compensated=comp.not_compensated(args.algorithm) if comp else {})
    if stage == "embedded" and spec is not None and stored_range(spec.fit, "u") is None and args.stage == "auto":
        print(f"hyst track: note: {args.params} records no identified input range (fit.u_min, fit.u_max): the "
              "embedded PEA stage (0-150 V) was simulated; for another stage give --stage params --v-min V "
              "--v-max V", file=sys.stderr)
    if comp is not None and comp.not_compensated(args.algorithm) and not args.json:
        print(f"note: {comp.describe(args.algorithm)}", file=sys.stderr)
    if args.json:
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
    else:
        pos = f" (stage position {res.rmse_position * 1e6:.4f} um)" if res.x is not None else ""
        where = "the embedded PEA stage" if stage == "embedded" else \
            f"the params file's stage ({limits.v_min:.4g}..{limits.v_max:.4g} V)"
        print(f"{args.algorithm} tracking {args.reference} on {where} for {args.seconds:g} s at {args.rate:g} Hz: "
              f"RMSE {res.rmse * 1e6:.4f} um{pos}, MAE {res.mae * 1e6:.4f} um, "
              f"command {out['u_min']:.1f}..{out['u_max']:.1f} V")
    return 0
