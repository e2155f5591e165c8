"""Start-up time of the ``hyst`` command (issue #13: ``--help`` and an immediate error in < 0.5 s idle).

Arguments are parsed and input paths checked before the numerical imports (numpy, scipy, numba, the models), so
a typo costs a fraction of a second even on a loaded machine. Median of 5 runs each, load average beside it.

Run: ``python bench/bench_startup.py`` or ``python bench/run_all.py startup``.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

TARGET = 0.5  # s, idle


def _hyst() -> list[str]:
    exe = Path(sys.executable).with_name("hyst")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "hyst_model.cli.main"]


def _median_seconds(argv: list[str], n: int = 5) -> tuple[float, int]:
    ts, rc = [], 0
    for _ in range(n):
        t0 = time.perf_counter()
        rc = subprocess.run(argv, capture_output=True, check=False).returncode
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), rc


def main() -> str:
    hyst = _hyst()
    cores = os.cpu_count() or 1
    lines = [f"{'command':<28}{'median':>10}{'exit':>6}  target {TARGET * 1e3:.0f} ms idle"]
    for label, args in (("hyst --help", ["--help"]), ("hyst fit nope.csv", ["fit", "nope.csv"]),
                        ("hyst diagnose nope.csv", ["diagnose", "nope.csv"])):
        load = os.getloadavg()[0]
        t, rc = _median_seconds(hyst + args)
        flag = "" if load <= cores else f"  (load {load:.1f} > {cores} cores: not an idle figure)"
        lines.append(f"{label:<28}{t * 1e3:>8.0f} ms{rc:>6}  load {load:.1f}{flag}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(main())
