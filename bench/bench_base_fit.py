"""How often the base MBW fit misses on effect-free generated records (hyst_sim.generator, kind ``none``).

Each record is an MBW stage plus sensor noise and nothing else, so the diagnosis's base fit (its own scaling,
hold-out split and fitter) can reach the noise floor; a fit that ends far above it would make any effect look
significant. Prints each record's training and held-out RMSE over the noise and the count of fits ≥ 2× and ≥ 5×.

Usage: ``python bench/bench_base_fit.py [--shapes thesis|wide] [--seed 23] [--n 200] [--jobs 2] [--rate 2000]
[--duration 8] [--json OUT]``; from ``bench/run_all.py`` 24 records. Case seeds are ``seed * 100000 + i``, as in
``bench_diagnose_accuracy.py``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # one BLAS thread per worker: the workers are the parallelism

import numpy as np  # noqa: E402 - after the BLAS thread variables above, which numpy reads at import


def run_case(args: tuple) -> dict:
    """Fit the base to one effect-free case; RMSE over the noise on training and held-out samples."""
    seed, shapes, rate, duration = args
    from hyst_model.diagnose.diagnose import _scales, default_fitter, validation_mask
    from hyst_model.spec import build_model
    from hyst_sim.generator import generate_case

    c = generate_case(seed, "none", shapes=shapes, rate=rate, duration=duration)
    m = build_model("mbw", (), dict(_scales(c.u, c.y), dt=float(c.t[1] - c.t[0])))
    t0 = time.perf_counter()
    th = default_fitter(m, c.t, c.u, c.y, None)
    sec = time.perf_counter() - t0
    val = validation_mask(c.t.size, c.u)
    e = c.y - m.simulate(th, c.t, c.u)
    return {"case": c.name, "train": float(np.sqrt(np.mean(e[~val] ** 2)) / c.noise),
            "val": float(np.sqrt(np.mean(e[val] ** 2)) / c.noise), "seconds": sec}


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", choices=("thesis", "wide"), default="thesis")
    ap.add_argument("--seed", type=int, default=23)
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--rate", type=float, default=2000.0)
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(["--n", "24"] if argv is None else argv)  # from run_all.py: a quick family
    cases = [(a.seed * 100000 + i, a.shapes, a.rate, a.duration) for i in range(a.n)]
    if a.jobs > 1:
        from multiprocessing import Pool
        with Pool(a.jobs) as pool:
            res = pool.map(run_case, cases, chunksize=1)
    else:
        res = [run_case(c) for c in cases]
    lines = [f"{r['case']:<40} train {r['train']:8.2f}  held out {r['val']:8.2f}  ({r['seconds']:.2f} s)"
             + ("  <<" if r["train"] >= 2.0 else "") for r in res]
    tr = np.array([r["train"] for r in res])
    lines.append(f"{len(res)} effect-free {a.shapes}-shape records: training RMSE ≥ 2x the noise on "
                 f"{int(np.sum(tr >= 2))}, ≥ 5x on {int(np.sum(tr >= 5))}; median {np.median(tr):.3f}x")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f)
    out = "\n".join(lines)
    print(out)
    return out


if __name__ == "__main__":
    sys.exit(0 if main(sys.argv[1:]) else 1)
