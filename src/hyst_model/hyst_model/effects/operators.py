"""Play (backlash) operators of an input: the basis of a Prandtl–Ishlinskii hysteresis, shared by the effects'
record starts and the diagnosis's loop-shape test."""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["plays"]


@njit(cache=True, nogil=True)
def plays(u: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Play (backlash) operators of ``u`` for each radius, each starting at ``u[0]``: z ← min(max(z, u − r), u + r).

    Returns an array of shape ``(u.size, radii.size)``; radius 0 gives ``u`` itself.
    """
    n, m = u.shape[0], radii.shape[0]
    out = np.empty((n, m))
    z = np.full(m, u[0])
    for k in range(n):
        for j in range(m):
            z[j] = min(max(z[j], u[k] - radii[j]), u[k] + radii[j])
            out[k, j] = z[j]
    return out
