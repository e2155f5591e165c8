"""What in a residual points to missing stage dynamics (for :meth:`.dynamics.DynamicsEffect.evidence`): a peak
of the residual-to-input spectrum (:func:`residual_peak`) and the input–residual coherence over a broadband
excitation (:func:`coherence_test`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["residual_peak", "coherence_test"]


def residual_peak(u: np.ndarray, r: np.ndarray, dt: float) -> float | None:
    """Frequency (Hz) where the residual's spectrum, relative to the input's, peaks; None if it does not.

    A lightly damped resonance that the model lacks leaves ringing at its frequency after every fast input
    change, so the residual-to-input power ratio has a clear maximum there (Welch estimates).
    """
    from scipy.signal import welch
    n = u.size
    nper = int(min(1024, max(64, n // 8)))
    if n < 4 * nper:
        return None
    f, Prr = welch(r, 1.0 / dt, nperseg=nper)
    _, Puu = welch(u - u.mean(), 1.0 / dt, nperseg=nper)
    ok = (f > 2.0 * f[1]) & (Puu > 1e-12 * Puu.max())
    if ok.sum() < 8:
        return None
    ratio = Prr[ok] / Puu[ok]
    i = int(np.argmax(ratio))
    if ratio[i] < 10.0 * float(np.median(ratio)):
        return None
    return float(f[ok][i])


def coherence_test(u: np.ndarray, r: np.ndarray, dt: float) -> tuple[float, str]:
    """For broadband inputs (multisines, noise, sweeps): is the residual a *linear, resonant* response to u?

    Welch coherence between input and residual, weighted by the input's power over the excited band: near 1
    when the residual is a linear filter of the input (missing dynamics), near 0 for noise or for nonlinear
    loop-shape errors. A peak of the residual's gain |P_ur/P_uu| inside the band marks a resonance.
    """
    from scipy.signal import coherence, csd, welch
    n = u.size
    nper = int(min(1024, max(64, n // 8)))
    if n < 4 * nper:
        return 0.0, ""
    fs = 1.0 / dt
    f, C = coherence(u, r, fs, nperseg=nper)
    _, Puu = welch(u, fs, nperseg=nper)
    _, Pur = csd(u, r, fs, nperseg=nper)
    band = Puu > 0.01 * Puu.max()
    if band.sum() < 8:  # a sine or a few lines: coherence says nothing about dynamics there
        return 0.0, ""
    coh = float(np.average(C[band], weights=Puu[band]))
    H = np.abs(Pur[band] / Puu[band])
    fb = f[band]
    i = int(np.argmax(H))
    peaked = 0 < i < H.size - 1 and H[i] > 3.0 * float(np.median(H))
    score = coh * (1.0 if peaked else 0.6)
    txt = (f"the residual is a linear response to the input (coherence {coh:.2f} over {fb[0]:.3g}–{fb[-1]:.3g} Hz)"
           + (f" whose gain peaks at {fb[i]:.3g} Hz ({H[i] / np.median(H):.0f}× its median) → a resonance of the "
              "stage the model lacks" if peaked else " → linear dynamics the model lacks"))
    return float(score), txt
