"""Cost of the simulated plant (hyst_sim.plant): per-sample step() from Python and vectorised run().

``main() -> str`` returns a markdown table; run via ``make bench`` or ``python bench/bench_plant.py``.
"""
from __future__ import annotations

import time

import numpy as np

from hyst_sim.plant import Plant, PlantConfig

N_STEP = 20_000
N_RUN = 1_000_000


def _configs() -> list[tuple[str, PlantConfig]]:
    default = PlantConfig.for_profile("pea", 2000.0)
    every = default.with_strengths(creep=0.01, asymmetry=0.02, dynamics=350.0, delay=3, drift=4e-9,
                                   saturation=0.05)
    bare = PlantConfig.for_profile("pea", 2000.0, sensor=False)
    return [("MBW only (no effects)", bare), ("default (MBW + 2 nm noise + 2 nm quantisation)", default),
            ("all eight effects on", every)]


def _best_of(fn, repeats: int = 3) -> float:
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> str:
    t = np.arange(N_RUN) / 2000.0
    u = 75.0 - 75.0 * np.cos(2 * np.pi * 10.0 * t)
    rows = ["| plant | step() cost (µs/sample) | run() throughput (Msamples/s) | 2 kHz budget used by step() |",
            "|---|---|---|---|"]
    for name, cfg in _configs():
        plant = Plant(cfg)
        plant.run(u[:100])            # compile / warm caches
        us = u[:N_STEP].tolist()

        def steps():
            plant.reset()
            for v in us:
                plant.step(v)

        def run():
            plant.reset()
            plant.run(u)

        step_us = _best_of(steps) / N_STEP * 1e6
        run_rate = N_RUN / _best_of(run) / 1e6
        rows.append(f"| {name} | {step_us:.2f} | {run_rate:.1f} | {step_us / 500.0 * 100:.2f} % |")
    return "\n".join(rows) + (f"\n\nstep(): {N_STEP} Python calls; run(): {N_RUN} samples (10 Hz full-stroke sine at "
                              "2 kHz); best of 3.")


if __name__ == "__main__":
    print(main())
