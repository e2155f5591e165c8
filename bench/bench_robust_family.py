"""Robust tracking on randomised stages: the lab workflow (issue #11) on a family, not on the shipped scenarios.

Each case draws, from its own seed: the actuator (PEA 0–150 V or GMA ±5 V), an MBW truth perturbed from the
profile's default stage (ζ1 ±15 %, ζ2 ±30 %, gain ±20 %, offset), and hidden effects of the sim plant at random
strengths and shapes — none, one, or a pair of creep, asymmetry, delay, drift, saturation and a stage resonance.
For each case the workflow is what a user runs: play the open-loop identification excitation on the stage,
diagnose the record, then track with DPPC, DMRAC and the open-loop inverse (feedforward), each with the
diagnosis's base MBW and with its final (extended) model, on a fresh stage (other noise). The same workflow on the
case's effect-free twin (same truth, same noise) gives the "no-effect level" the issue's criteria compare with:
DPPC and DMRAC with the extended model within 2× of it on sines up to 30 Hz, feedforward within 3×.
Errors are the sensor's reading against the reference, as a user measures them; the last column gives each
law's error on the stage's true position (a simulation knows it) against the same no-effect level: the sim's drift
is the sensor's offset drifting, which no open-loop law can see and which leaves the stage where it was sent,
while a feedback law follows the reading and moves the stage by the drift.

References sit mid-stroke with 20 % of the effect-free stage's static travel as amplitude (about 15 ± 6 µm on a
PEA, 0 ± 8 µm on a GMA), so every case asks only what its stage can reach within a few ms.
Nothing here was tuned to the cases: strengths and shapes are drawn from ranges a lab sees, and the seed fixes
everything.

Usage: ``python bench/bench_robust_family.py [--n 24] [--seed 100] [--seconds 1.5]``.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace

import numpy as np

from bench_robust_tracking import RATE, identify, track_both

EFFECTS = ("creep", "asymmetry", "delay", "drift", "saturation", "dynamics")
SINES = (1.0, 10.0, 30.0)
ALGS = (("dppc", 2.0), ("dmrac", 2.0), ("open_loop", 3.0))


@dataclass(frozen=True)
class StageCase:
    """One randomised stage: profile, perturbed MBW truth and hidden effect strengths/shapes."""

    seed: int
    profile: str
    mbw: object
    effects: dict           # name -> (strength, {shape setting: value})

    @property
    def name(self) -> str:
        eff = "+".join(f"{k}={v[0]:.3g}" for k, v in self.effects.items()) or "none"
        return f"{self.seed}:{self.profile}:{eff}"


def _draw_effect(name: str, rng: np.random.Generator) -> tuple[float, dict]:
    """A strength and shape from ranges a lab stage shows (units of :mod:`hyst_sim.truth_effects`)."""
    if name == "creep":
        return rng.uniform(0.01, 0.06), {}
    if name == "asymmetry":
        return rng.choice([-1.0, 1.0]) * rng.uniform(0.02, 0.1), {}
    if name == "delay":
        return int(rng.integers(1, 7)), {}
    if name == "drift":
        return rng.uniform(5e-9, 5e-8), {"period": rng.uniform(10.0, 120.0)}
    if name == "saturation":
        return rng.uniform(0.05, 0.2), {}
    if name == "dynamics":
        return rng.uniform(300.0, 900.0), {"damping": rng.uniform(0.03, 0.12)}
    raise ValueError(name)


def draw_case(seed: int) -> StageCase:
    """Case ``seed`` of the family: about 1 in 6 without an effect, 1 in 4 with a pair, the rest one effect."""
    from hyst_model.core import stage_model  # the profile's default stage model

    rng = np.random.default_rng(seed)
    profile = "pea" if rng.random() < 0.6 else "gma"
    p = stage_model(profile)
    mbw = p.replace(zeta1=p.zeta1 * rng.uniform(0.85, 1.15), zeta2=p.zeta2 * rng.uniform(0.7, 1.3),
                    y_scale=p.y_scale * rng.uniform(0.8, 1.2))
    k = rng.random()
    n = 0 if k < 1 / 6 else (2 if k > 0.75 else 1)
    names = list(rng.choice(EFFECTS, size=n, replace=False))
    return StageCase(seed, profile, mbw, {e: _draw_effect(e, rng) for e in names})


def plant_factory(case: StageCase, with_effects: bool = True):
    """``seed -> plant`` for the case (or its effect-free twin)."""
    from hyst_bringup.loop import SimPlant
    from hyst_sim.plant import Plant, PlantConfig

    def make(seed: int):
        cfg = PlantConfig.for_profile(case.profile, rate=RATE, mbw=case.mbw, seed=seed)
        if with_effects and case.effects:
            eff = cfg.effects
            for name, (strength, shape) in case.effects.items():
                obj = replace(getattr(eff, name), strength=strength, **shape)
                eff = eff.with_effects(**{name: obj})
            cfg = replace(cfg, effects=eff)
        return SimPlant(Plant(cfg))
    return make


def _limits_and_excitation(profile: str, seed: int):
    from hyst_control.excitation import ExcitationSpec
    from hyst_common.profiles import GMA_LIMITS, PEA_LIMITS

    lim = PEA_LIMITS if profile == "pea" else GMA_LIMITS
    return lim, ExcitationSpec(v_min=lim.v_min, v_max=lim.v_max, dt=1.0 / RATE, seed=seed)


def declare_drift_side(spec, side: str | None):
    """The params ``spec`` with ``drift.side`` set where it holds a drift (what a user who knows which part of the
    rig drifts writes in the file: a record cannot tell); unchanged otherwise."""
    if side is None or "drift" not in spec.effects:
        return spec
    return replace(spec, config={**spec.config, "drift.side": side})


def run_case(case: StageCase, seconds: float, drift_side: str | None = None) -> dict:
    """Identify the case and its twin, track every sine with every law; RMSEs (m) and the diagnosis.
    ``drift_side``: declare the identified drift's side (``stage`` or ``sensor``) before tracking."""
    from hyst_control.reference import Reference

    lim, ex = _limits_and_excitation(case.profile, case.seed)
    # references inside what this stage reaches: mid-stroke ± 20 % of its static travel over the voltage range
    # (a fixed 15 ± 10 µm asked a weak PEA stage with creep for more than 150 V at 10 Hz: 255 nm of clipping;
    # ± 30 % still clipped at 10-30 Hz with strong creep, which moves ~25 % of the travel only after seconds)
    twin = plant_factory(case, False)(0)
    y_lo, y_hi = twin.reset(lim.v_min), twin.reset(lim.v_max)
    mid, amp = 0.5 * (y_lo + y_hi), 0.2 * (y_hi - y_lo)
    out: dict = {"case": case}
    for tag, with_eff in (("stage", True), ("twin", False)):
        make = plant_factory(case, with_eff)
        base, ext, d = identify(make, seed=case.seed, excitation=ex)
        base, ext = declare_drift_side(base, drift_side), declare_drift_side(ext, drift_side)
        if tag == "stage":
            out["named"] = tuple(ext.effects)
        for f in SINES:
            ref = Reference(shape="sine", amplitude=amp, frequency=f, offset=mid)
            for alg, _ in ALGS:
                models = (("base", base), ("ext", ext)) if tag == "stage" else (("ext", ext),)
                for m, spec in models:
                    out[tag, m, alg, f], out[tag, m, alg, f, "x"] = track_both(spec, make, alg, ref, seconds,
                                                                               limits=lim)
    return out


def verdicts(r: dict) -> dict:
    """The issue's criteria for one case: worst ratio ext/twin per law over the sines, and ext vs base."""
    v = {}
    for alg, _ in ALGS:
        ratios = [r["stage", "ext", alg, f] / r["twin", "ext", alg, f] for f in SINES]
        v[alg] = max(ratios) if all(np.isfinite(ratios)) else float("inf")
        v[alg + "_better"] = all(r["stage", "ext", alg, f] <= 1.05 * r["stage", "base", alg, f] for f in SINES)
        # where the stage itself went (a simulation knows it; a sensor's own drift is no stage error), against the
        # same no-effect level (the twin's reading: its true position is noise-free, a ratio to it measures nothing)
        ratios = [r["stage", "ext", alg, f, "x"] / r["twin", "ext", alg, f] for f in SINES]
        v[alg + "_x"] = max(ratios) if all(np.isfinite(ratios)) else float("inf")
    return v


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--seed", type=int, default=100, help="first case seed (cases seed, seed+1, ...)")
    ap.add_argument("--seconds", type=float, default=1.5)
    ap.add_argument("--drift-side", choices=("stage", "sensor"), default=None,
                    help="declare the identified drift's side before tracking (the sim's drift is its sensor's)")
    args = ap.parse_args(argv if argv is not None else [])
    t0 = time.perf_counter()
    lines = ["| case | diagnosed | " + " | ".join(f"{a} ext/none (worst sine)" for a, _ in ALGS)
             + " | ext no worse than base | on the stage's true position |", "|---|---|" + "---|" * (len(ALGS) + 2)]
    met = {a: 0 for a, _ in ALGS}
    met_x = {a: 0 for a, _ in ALGS}
    rows = []
    for i in range(args.n):
        case = draw_case(args.seed + i)
        r = run_case(case, args.seconds, args.drift_side)
        v = verdicts(r)
        rows.append((case, v))
        for a, lim in ALGS:
            met[a] += v[a] <= lim
            met_x[a] += v[a + "_x"] <= lim
        cells = [f"{v[a]:.2g}×{'' if v[a] <= lim else ' **NO**'}" for a, lim in ALGS]
        better = "/".join("y" if v[a + "_better"] else "n" for a, _ in ALGS)
        better += " | " + " / ".join(f"{v[a + '_x']:.2g}×" for a, _ in ALGS)
        lines.append(f"| {case.name} | {','.join(r['named']) or 'none'} | " + " | ".join(cells) + f" | {better} |")
        print(f"[{time.perf_counter() - t0:6.0f} s] {lines[-1]}", file=sys.stderr, flush=True)
    lines.append("")
    lines.append("Met (of %d cases): " % args.n + "; ".join(f"{a} ext ≤ {lim:g}× no-effect level: {met[a]}"
                                                        for a, lim in ALGS)
                 + "; on the stage's true position (sim only): " + ", ".join(f"{a} {met_x[a]}" for a, _ in ALGS))
    lines.append(f"({time.perf_counter() - t0:.0f} s, {args.seconds:g} s per run at {RATE:g} Hz, first seed "
                 f"{args.seed})")
    return "\n".join(lines)


if __name__ == "__main__":
    print(main(sys.argv[1:]))
