"""MBW simulation speed: the compiled recursion (numba) vs a plain Python loop, single and batched (swarm)."""
from __future__ import annotations

import time

import numpy as np


def _python_loop(p, u):
    y = np.empty(u.size)
    yp, up = 0.0, u[0]
    for k in range(u.size):
        nu = u[k] - p[7] * up
        v = abs(u[k] - up)
        yp = (p[6] * yp + (p[0] + p[1] * v) * nu - (p[2] + p[3] * v) * abs(nu) * yp
              - (p[4] + p[5] * v) * nu * abs(yp))
        y[k] = yp
        up = u[k]
    return y


def _best(fn, repeat=5):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> str:
    from hyst_model.core import THESIS_TABLE41, mbw_simulate, mbw_simulate_batch
    from hyst_model.core.sensitivity import mbw_simulate_sens

    p = THESIS_TABLE41.vector
    n = 200_000
    u = 10 * np.sin(2 * np.pi * np.arange(n) / 2000.0)
    mbw_simulate(p, u[:10], 0.0, np.nan)
    P = np.tile(p, (40, 1)) * np.linspace(0.98, 1.02, 40)[:, None]
    mbw_simulate_batch(P, u[:10], np.zeros(40))
    mbw_simulate_sens(p, u[:10], 0.0, np.zeros(8))
    t_py = _best(lambda: _python_loop(p, u[:20000]), 2) * n / 20000
    t_nb = _best(lambda: mbw_simulate(p, u, 0.0, np.nan))
    t_batch = _best(lambda: mbw_simulate_batch(P, u, np.zeros(40)), 3)
    t_sens = _best(lambda: mbw_simulate_sens(p, u, 0.0, np.zeros(8)), 3)
    assert np.allclose(_python_loop(p, u[:5000]), mbw_simulate(p, u[:5000], 0.0, np.nan))
    rows = ["| implementation | samples/s | speed-up vs Python |", "|---|---|---|",
            f"| plain Python loop | {n / t_py:,.0f} | 1x |",
            f"| numba `mbw_simulate` | {n / t_nb:,.0f} | {t_py / t_nb:,.0f}x |",
            f"| numba `mbw_simulate_batch`, 40 parameter sets (swarm), parallel | {40 * n / t_batch:,.0f} | "
            f"{40 * t_py / t_batch:,.0f}x |",
            f"| numba `mbw_simulate_sens` (output + 8 sensitivities) | {n / t_sens:,.0f} | {t_py / t_sens:,.0f}x |",
            "", f"{n:,} samples per run, best of several runs."]
    return "\n".join(rows)


if __name__ == "__main__":
    print(main())
