"""Does the diagnosis depend on the amplifier's voltage range? Generated records, the input rescaled.

The MBW recursion is exact under an input scale (``u_scale``: ν and v_u scale with it), and the library's effects
act on the output or in samples, so a record whose input column is multiplied by ``a`` is the same stage behind
another amplifier range (a GMA's ±5 V as ±10 or ±60 V; a PEA's 0–150 V as 0–50 or 0–300 V). A diagnosis that
generalises over actuators gives the same answer on both; where it does not, some part of it works in volts.
Each case of :func:`hyst_sim.generator.generate_case` (the accuracy bench's family) is diagnosed as generated and
with its input scaled by a factor drawn per case from ``--factors``; the answers are compared.

Usage: ``python bench/bench_diagnose_range.py [--seed 60] [--n 24] [--jobs 2] [--factors 0.3,2,6]``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # one BLAS thread per worker: the workers are the parallelism

import numpy as np  # noqa: E402 - after the BLAS thread variables above

KINDS = ("single_large", "single_small", "none", "pair")


def run_case(args: tuple) -> dict:
    """Diagnose one case as generated and with its input scaled by ``a``: the two answers and base errors."""
    seed, kind, a = args
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case

    c = generate_case(seed, kind)
    out = {"case": c.name, "expected": list(c.expected), "factor": a}
    for key, u in (("as_is", c.u), ("scaled", a * c.u)):
        d = diagnose(c.t, u, c.y)
        named = [x.effect for x in d.candidates][:len(d.ladder[-1].effects)] \
            if d.missing not in ("none", "unexplained") else [d.missing]
        out[key] = {"named": named, "base": d.baseline_rmse / d.noise, "final": d.ladder[-1].rmse / d.noise}
    return out


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=60, help="family seed (cases use seed*100000 + i)")
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--factors", default="0.3,2,6", help="input scale factors, one drawn per case")
    a = ap.parse_args(["--n", "8"] if argv is None else argv)  # run_all.py: a quick family
    factors = [float(x) for x in a.factors.split(",")]
    rng = np.random.default_rng(a.seed)
    jobs = [(a.seed * 100000 + i, KINDS[i % len(KINDS)], float(rng.choice(factors))) for i in range(a.n)]
    t0 = time.perf_counter()
    lines: list[str] = []
    if a.jobs > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(run_case, jobs))
    else:
        rows = [run_case(j) for j in jobs]
    same = 0
    for r in rows:
        s, x = r["as_is"], r["scaled"]
        agree = s["named"] == x["named"]
        same += agree
        lines.append(f"{r['case']:45s} ×{r['factor']:<4g} expected {','.join(r['expected']):22s} as is "
                     f"{','.join(s['named']):24s} ({s['base']:.3g}→{s['final']:.3g}×)  scaled "
                     f"{','.join(x['named']):24s} ({x['base']:.3g}→{x['final']:.3g}×){'' if agree else '  DIFFERS'}")
    lines.append(f"\nsame answer on {same} / {len(rows)} cases; {time.perf_counter() - t0:.0f} s")
    return "\n".join(lines)


if __name__ == "__main__":
    print(main(sys.argv[1:]))
