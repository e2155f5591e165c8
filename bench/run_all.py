"""Run every benchmark under bench/ (files bench_*.py exposing ``main() -> str``) and print their tables.

Usage: ``python bench/run_all.py [NAME ...]`` — NAME filters by substring of the file name.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    here = Path(__file__).resolve().parent
    files = sorted(here.glob("bench_*.py"))
    if argv:
        files = [f for f in files if any(a in f.stem for a in argv)]
    if not files:
        print("no benchmarks matched", file=sys.stderr)
        return 1
    failed = 0
    for f in files:
        spec = importlib.util.spec_from_file_location(f.stem, f)
        mod = importlib.util.module_from_spec(spec)
        # registered under its own name: dataclasses look their module up there, and a worker pool unpickles
        # the bench's functions by module name
        sys.modules[f.stem] = mod
        t0 = time.perf_counter()
        load = os.getloadavg()[0]
        cores = os.cpu_count() or 1
        note = f" — load {load:.1f} > {cores} cores: timings not representative" if load > cores else ""
        print(f"\n## {f.stem} (load average {load:.1f}{note})\n", flush=True)
        try:
            spec.loader.exec_module(mod)
            print(mod.main())
        except Exception as err:  # noqa: BLE001 - one broken bench must not hide the others
            failed += 1
            print(f"FAILED: {type(err).__name__}: {err}")
        print(f"\n({time.perf_counter() - t0:.1f} s)", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
