"""Bouc-Wen hysteretic benchmark: hyst's multisine test e_RMS next to the published results.

Runs tools/boucwen_benchmark.py (training on the dynoNet-generated 5-period multisine, period 5 held out, both
``dynamics`` structures fitted, the better one kept, test in simulation mode) and returns its markdown table with
the wall time of each fit.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path


def _tool():
    path = Path(__file__).resolve().parents[1] / "tools" / "boucwen_benchmark.py"
    spec = importlib.util.spec_from_file_location("boucwen_benchmark", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def main() -> str:
    bb = _tool()
    r = bb.run(quick=False, progress=lambda s: None)
    times = ", ".join(f"{k} {v:.1f} s" for k, v in r.seconds.items())
    return bb.table(r) + f"\n\nFit wall times: {times}."


if __name__ == "__main__":
    print(main())
