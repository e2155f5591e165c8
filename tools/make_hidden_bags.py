#!/usr/bin/env python3
"""Generate the hidden-effect bags ``bags/hidden/<scenario>/`` from the simulated stage and its scenario files.

Each bag is what a lab would record to identify a piezo stage: 40 s at 1 kHz of ``/stage/state``
(``sensor_msgs/msg/JointState``: displacement in ``position[0]``, applied voltage in ``effort[0]``), MCAP with
zstd chunk compression. The excitation (:func:`excitation`) alternates steps with holds (creep and drift show
during holds) and sines of several frequencies and amplitudes (loops, rate dependence, delay and dynamics show
while the input moves), and repeats both kinds in the last quarter so held-out validation sees every kind of
motion. The stage is :class:`hyst_sim.plant.Plant` with ``PlantConfig.from_scenario(hidden_<name>.yaml)``: the
thesis's PEA stage (Table 4.1 MBW, 0–150 V, amplifier slew limit, 2 nm noise and resolution) plus the scenario's
hidden effects, whose names and strengths this script never prints.

Usage::

    python tools/make_hidden_bags.py [--out bags/hidden] [--force] [--only creep,none]
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

RATE = 1000.0
DURATION = 40.0


def excitation(rate: float = RATE, duration: float = DURATION) -> tuple[np.ndarray, np.ndarray]:
    """Commanded voltage (V) of the identification experiment: steps/holds and sines, within 0–150 V."""
    t = np.arange(int(round(duration * rate))) / rate
    u = np.zeros_like(t)
    k = duration / DURATION  # the schedule below is written for 40 s and stretched to ``duration``

    def steps(t0, t1, levels):
        t0, t1 = k * t0, k * t1
        seg = (t1 - t0) / len(levels)
        for i, lv in enumerate(levels):
            u[(t >= t0 + i * seg) & (t < t0 + (i + 1) * seg)] = lv

    def sines(t0, t1, parts):
        t0, t1 = k * t0, k * t1
        seg = (t1 - t0) / len(parts)
        for i, (f, a) in enumerate(parts):
            m = (t >= t0 + i * seg) & (t < t0 + (i + 1) * seg)
            u[m] = 75.0 - a * np.cos(2 * np.pi * f * (t[m] - t0 - i * seg))

    # Sine segments (whole periods at 40 s) start and end at 75 - a, so each joins with one small step.
    steps(0, 10, [0, 60, 120, 30, 150])
    sines(10, 20, [(0.4, 70), (2, 50), (4.8, 30), (10, 20)])
    steps(20, 25, [0, 100])
    sines(25, 30, [(1, 60), (6, 40)])
    steps(30, 35, [140, 20])
    sines(35, 40, [(0.8, 65), (4, 45)])
    return t, u


def scenario_dir() -> Path:
    import hyst_sim
    return Path(hyst_sim.__file__).resolve().parent / "data" / "scenarios"


def make_bag(scenario: Path, out: Path, seed: int = 0) -> tuple[Path, int]:
    """Simulate one scenario on :func:`excitation` and write its bag; return (path, bytes)."""
    from hyst_model.io.bag import write_state_bag
    from hyst_sim.plant import Plant, PlantConfig

    cfg = PlantConfig.from_scenario(scenario, base=PlantConfig.for_profile("pea", rate=RATE, seed=seed))
    plant = Plant(cfg)
    plant.reset()
    t, u_cmd = excitation()
    r = plant.run(u_cmd)
    path = write_state_bag(out, t, r.u_applied, r.y, t0_ns=1_700_000_000_000_000_000)
    size = sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())
    return Path(path), size


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "bags" / "hidden"))
    ap.add_argument("--force", action="store_true", help="replace existing bags")
    ap.add_argument("--only", default="", help="comma-separated scenario names (default all)")
    args = ap.parse_args(argv)
    files = sorted(scenario_dir().glob("hidden_*.yaml"))
    if not files:
        print(f"make_hidden_bags: no scenario files in {scenario_dir()}", file=sys.stderr)
        return 2
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for f in files:
        name = f.stem.removeprefix("hidden_")
        if only and name not in only:
            continue
        dest = out / name
        if dest.exists():
            if not args.force:
                print(f"{dest}: exists, skipped (use --force to replace)")
                continue
            shutil.rmtree(dest)
        path, size = make_bag(f, dest)
        print(f"{path}: {size / 1e6:.2f} MB")
        if size > 2e6:
            print(f"make_hidden_bags: {path} is larger than 2 MB", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
