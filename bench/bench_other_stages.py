"""Stages other than the rig's two: identify and track on randomised amplifier ranges, strokes and loop shapes.

Each case draws, from its own seed: a bipolar (±U, U log-uniform in 2–100 V) or unipolar (0–U, U in 10–1000 V)
amplifier, a stroke log-uniform in 5–100 µm, a loop shape from the generator's wide MBW family
(:func:`hyst_sim.generator.cases._wide_truth`: ζ, ψ, α, δ drawn wide, loops 3–25 % of the stroke; redrawn where
it overshoots its travel on the excitation, see :func:`draw`), a rate of 1 or
2 kHz and the sensor's 2 nm noise and quantisation. The workflow is a user's on such a stage:
``hyst excite --profile custom`` over the range → record on the true stage → ``hyst fit`` → track ``sine:10``
and ``c1`` placed on the stage's stroke with DPPC, DMRAC, PID (defaults moved to the model's static gain,
:func:`hyst_control.pid.gains_for`) and the open-loop inverse, each on the fitted model, on a fresh true stage.
The PID also runs with the PEA's SI defaults (``pid_si``), to show what the scaling does.

Printed per case: the stage, the fit's validation RMSE over the noise, and per law the tracking RMSE over the
noise (sine:10 / c1); ``osc`` marks a law the oscillation watch derated, ``sat`` one whose commands sat on a
range end for over 1 % of the run (the reference is beyond what the stage reaches at that speed: a slow memory
makes the 10 Hz reach smaller than the rest stroke the reference is placed on), ``out`` commands beyond the range,
``nan`` a diverged loop. The summary gives medians over all cases and over those where no law saturated.
Nothing was tuned to these cases.

Usage: ``python bench/bench_other_stages.py [--n 12] [--seed 7000] [--seconds 1]``.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ALGS = ("dppc", "dmrac", "pid", "pid_si", "open_loop")
REFS = ("sine:10", "c1")


def draw(seed: int):
    """(truth MBW, limits, rate, profile) of one case.

    A wide shape is normalised on a slow sine; on the excitation's sweep and multisine some overshoot their travel
    several times over (rate terms), where the sim's end stops then *are* the stage. A real stage stays inside its
    travel, so a shape that reaches a stop on the identification excitation is drawn again (up to 50 times).
    """
    from hyst_common.profiles import custom_limits, get_profile
    from hyst_sim.generator.cases import _wide_truth

    rng = np.random.default_rng(seed)
    bipolar = bool(rng.random() < 0.5)
    prof = "gma" if bipolar else "pea"
    span = float(np.exp(rng.uniform(np.log(2.0), np.log(100.0)))) if bipolar else \
        float(np.exp(rng.uniform(np.log(10.0), np.log(1000.0))))
    lo, hi = (-span, span) if bipolar else (0.0, span)
    stroke = float(np.exp(rng.uniform(np.log(5e-6), np.log(100e-6))))
    rate = float(rng.choice([1000.0, 2000.0]))
    lim = custom_limits(lo, hi)
    pr = get_profile(prof)
    u = _excitation(lim, rate, seed)
    for _ in range(50):
        p = _wide_truth(prof, rng)
        p = p.replace(u_scale=p.u_scale * (hi - lo) / (pr.v_max - pr.v_min), y_scale=p.y_scale * stroke / pr.stroke,
                      offset=p.offset * stroke / pr.stroke)
        if not _plant(p, lim, rate, prof, seed).plant.run(u).at_stop.any():
            return p, lim, rate, prof
    raise RuntimeError(f"case {seed}: no wide shape stays inside its travel in 50 draws")


def _excitation(lim, rate: float, seed: int) -> np.ndarray:
    """The identification excitation over the stage's range (``hyst excite --profile custom``'s defaults)."""
    from hyst_control.excitation import ExcitationSpec, build_excitation

    return build_excitation(ExcitationSpec(v_min=lim.v_min, v_max=lim.v_max, slew_max=lim.slew_max,
                                           dt=1.0 / rate, seed=seed % 1000)).u


def _plant(p, lim, rate, prof, seed):
    from hyst_bringup.loop import SimPlant
    from hyst_sim.plant import Plant, PlantConfig

    cfg = PlantConfig.for_profile(prof, rate, seed=seed, mbw=p, v_min=lim.v_min, v_max=lim.v_max,
                                  slew_max=lim.slew_max, v_init=lim.v_safe)
    return SimPlant(Plant(cfg))


def run_case(seed: int, seconds: float, work: Path) -> dict:
    from hyst_bringup.loop import run_closed_loop
    from hyst_control.compensation import from_params
    from hyst_control.controllers import make_supervised
    from hyst_control.pid import gains_for
    from hyst_control.reference import parse_reference
    from hyst_model.cli.main import main as hyst
    from hyst_model.io.csvio import write_csv
    from hyst_model.io.params_file import read_params

    p, lim, rate, prof = draw(seed)
    u = _excitation(lim, rate, seed)
    t = np.arange(u.size) / rate
    rec = _plant(p, lim, rate, prof, seed)
    rec.reset(float(u[0]))
    y = np.array([rec.step(float(v)) for v in u])
    csv, par = work / f"r{seed}.csv", work / f"p{seed}.yaml"
    write_csv(csv, {"t": t, "u": u, "y": y}, force=True)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):  # its table
        rc = hyst(["fit", str(csv), "--out", str(par), "--quiet", "--force"])
    if rc != 0:
        return {"seed": seed, "error": "fit failed"}
    spec = read_params(par)
    model, comp = from_params(spec, 1.0 / rate)
    noise = 2e-9
    stroke = rec.plant.stroke_range
    out = {"seed": seed, "range": (lim.v_min, lim.v_max), "stroke": stroke[1] - stroke[0], "rate": rate,
           "fit": float(spec.fit["rmse"]) / noise}
    for alg in ALGS:
        law = "pid" if alg == "pid_si" else alg
        gains = gains_for(model, lim.v_min, lim.v_max) if alg == "pid" else None
        res = []
        for ref in REFS:
            ctrl = make_supervised(law, model, 1.0 / rate, lim, gains=gains, compensation=comp)
            try:
                r = run_closed_loop(ctrl, parse_reference(ref, stroke=stroke), seconds,
                                    plant=_plant(p, lim, rate, prof, seed + 1))
                e = r.rmse / noise
                flag = ("osc" if ctrl.events else "") + ("sat" if r.at_limits(lim.v_min, lim.v_max) > 0.01 else "") + \
                    ("out" if r.u.min() < lim.v_min - 1e-9 or r.u.max() > lim.v_max + 1e-9 else "")
            except Exception as err:  # noqa: BLE001 - a diverged loop is a result, not a crash of the bench
                e, flag = math.nan, type(err).__name__
            res.append((e, flag))
        out[alg] = res
    return out


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=12)
    ap.add_argument("--seed", type=int, default=7000)
    ap.add_argument("--seconds", type=float, default=1.0)
    a = ap.parse_args(["--n", "4", "--seconds", "0.5"] if argv is None else argv)  # run_all.py: a quick family
    t0 = time.perf_counter()
    lines: list[str] = []
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(a.n):
            rows.append(run_case(a.seed + i, a.seconds, Path(tmp)))
            r = rows[-1]
            if "error" in r:
                lines.append(f"{r['seed']}: {r['error']}")
                continue
            cells = "  ".join(f"{alg} " + "/".join(f"{e:.3g}{f}" for e, f in r[alg]) for alg in ALGS)
            lines.append(f"{r['seed']}  {r['range'][0]:+.4g}..{r['range'][1]:.4g} V  {r['stroke'] * 1e6:5.1f} um  "
                         f"{r['rate']:.0f} Hz  fit {r['fit']:.2f}x   {cells}")
    ok = [r for r in rows if "error" not in r]
    label, sub = "all", ok
    lines.append(f"\nRMSE over the 2 nm noise over {len(sub)} stages ({label}): median, worst, laws flagged:")
    for alg in ALGS:
        for k, ref in enumerate(REFS):
            reach = [r for r in sub if not any("sat" in r[a][k][1] for a in ALGS if a != "pid_si")]
            v = np.array([r[alg][k][0] for r in sub])
            w = np.array([r[alg][k][0] for r in reach])
            flagged = sum(1 for r in sub if r[alg][k][1])
            lines.append(f"  {alg:9s} {ref:8s} median {np.nanmedian(v):8.3g}  worst {np.nanmax(v):8.3g}  "
                         f"flagged {flagged}/{len(sub)}  diverged {int(np.sum(~np.isfinite(v)))}   reachable "
                         f"({w.size}): median {np.nanmedian(w) if w.size else math.nan:8.3g}  worst "
                         f"{np.nanmax(w) if w.size else math.nan:8.3g}")
    lines.append(f"{time.perf_counter() - t0:.0f} s")
    return "\n".join(lines)


if __name__ == "__main__":
    print(main(sys.argv[1:]))
