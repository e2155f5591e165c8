"""Start-up time of the ``hyst`` entry point (issue 13: < 0.5 s idle for --help and an immediate error).

Run: ``.venv/bin/python bench/bench_startup.py``; prints the median of 5 runs and the load average beside it."""
import os
import shutil
import statistics
import subprocess
import sys
import time


def _time(argv, n=5):
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        subprocess.run(argv, capture_output=True, check=False)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main() -> int:
    hyst = shutil.which("hyst") or os.path.join(os.path.dirname(sys.executable), "hyst")
    load = os.getloadavg()[0]
    for name, argv in (("hyst --help", [hyst, "--help"]), ("hyst fit nope.csv", [hyst, "fit", "nope.csv"])):
        t = _time(argv)
        note = "" if load < 1.5 else "  (machine loaded: not an idle figure)"
        print(f"startup  {name:<20} median {t * 1e3:7.1f} ms  target 500 ms  load {load:.1f}{note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
