"""The numerical kernels of the ``dynamics`` effect (:mod:`.dynamics` describes the model): the exact ZOH/FOH
discretisation of the series resonance and its numba recursion (:func:`series_filter`), the RK4 integration of
the Bouc-Wen mass-spring-damper (:func:`msd_bw_simulate`) and the input interpolation between samples
(:func:`upsample`). Also used by the controllers' resonance inverse.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import expm

from ..errors import EffectError

__all__ = ["series_filter", "zoh_matrices", "msd_bw_simulate", "upsample", "HOLDS"]

HOLDS = ("zoh", "foh")

def _expm_with_input(fn: float, zeta: float, dt: float, ramp: bool,
                     second: tuple[float, float] | None = None) -> np.ndarray:
    """exp(M·dt) of the resonance (y, ẏ) augmented by its input (held, or a ramp: input and slope states).

    ``second = (fn2, zeta2)``: a second mode driven by the first's displacement, states (y1, ẏ1, y2, ẏ2) — the
    cascade discretised as one system (a stage between one DAC and one ADC has one hold, whatever its modes).
    """
    modes = [(fn, zeta)] + ([second] if second is not None else [])
    ns = 2 * len(modes)
    n = ns + (2 if ramp else 1)
    M = np.zeros((n, n))
    for i, (f, z) in enumerate(modes):
        wn = 2.0 * np.pi * f
        M[2 * i, 2 * i + 1] = 1.0
        M[2 * i + 1, 2 * i] = -wn * wn
        M[2 * i + 1, 2 * i + 1] = -2.0 * z * wn
        M[2 * i + 1, ns if i == 0 else 2 * i - 2] = wn * wn  # driven by the input, or by the mode before
    if ramp:
        M[ns, ns + 1] = 1.0  # input slope state
    return expm(M * dt)


def _foh_matrices(fn: float, zeta: float, dt: float, second: tuple[float, float] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation of ωn²/(s²+2ζωn s+ωn²) for a piecewise-linear input: Φ, Γ1, Γ2 (see series_filter)."""
    E = _expm_with_input(fn, zeta, dt, ramp=True, second=second)
    ns = 2 if second is None else 4
    return E[:ns, :ns].copy(), E[:ns, ns].copy(), E[:ns, ns + 1].copy() / dt


def zoh_matrices(fn: float, zeta: float, dt: float, lag: float = 0.0, second: tuple[float, float] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation for a held input: ``s_{k+1} = Φ s_k + (Γ − Γ_b) x_k + Γ_b x_{k+1}``; returns Φ, Γ, Γ_b.

    ``lag`` (in sample periods, 0…1) is where the sensor samples relative to the hold: with ``lag = 0`` sample
    ``k+1`` reads the stage at the end of the period over which ``x_{k+1}`` was held (the MBW's own timing,
    Γ_b = Γ); with ``lag = 1`` the input ``x_k`` is held over the whole period before sample ``k+1`` (the textbook
    ZOH, ``scipy.signal.cont2discrete(method="zoh")``, strictly proper); in between, ``x_k`` still drives the
    stage for the first ``lag``·Δt of the period (Γ_b = ∫₀^{(1−lag)Δt} e^{Aτ}B dτ). Written in the first-order-
    hold form of :func:`_series_run` (Γ1 = Γ, Γ2 = Γ_b: Γ1 x_k + Γ2 (x_{k+1} − x_k)).
    """
    ns = 2 if second is None else 4  # ``second``: the cascade of two modes, states (y1, ẏ1, y2, ẏ2)
    E = _expm_with_input(fn, zeta, dt, ramp=False, second=second)
    g = E[:ns, ns].copy()
    if lag <= 0.0:
        return E[:ns, :ns].copy(), g, g.copy()
    gb = _expm_with_input(fn, zeta, (1.0 - min(lag, 1.0)) * dt, ramp=False, second=second)[:ns, ns].copy()
    return E[:ns, :ns].copy(), g, gb


@njit(cache=True, nogil=True)
def _series_run(phi: np.ndarray, g1: np.ndarray, g2: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = x.size
    y = np.empty(n)
    if n == 0:
        return y
    p = x[0]
    v = 0.0
    y[0] = p
    for k in range(n - 1):
        dx = x[k + 1] - x[k]
        pn = phi[0, 0] * p + phi[0, 1] * v + g1[0] * x[k] + g2[0] * dx
        vn = phi[1, 0] * p + phi[1, 1] * v + g1[1] * x[k] + g2[1] * dx
        p, v = pn, vn
        y[k + 1] = p
    return y


@njit(cache=True, nogil=True)
def _cascade_run(phi: np.ndarray, g1: np.ndarray, g2: np.ndarray, x: np.ndarray) -> np.ndarray:
    """:func:`_series_run` for any number of states, reading the last mode's displacement (state ns − 2)."""
    n = x.size
    ns = phi.shape[0]
    y = np.empty(n)
    if n == 0:
        return y
    s = np.zeros(ns)
    for i in range(0, ns, 2):
        s[i] = x[0]  # at rest at x[0]: every mode displaced by it, unit DC gain each
    sn = np.empty(ns)
    y[0] = x[0]
    for k in range(n - 1):
        dx = x[k + 1] - x[k]
        for i in range(ns):
            acc = g1[i] * x[k] + g2[i] * dx
            for j in range(ns):
                acc += phi[i, j] * s[j]
            sn[i] = acc
        s[:] = sn
        y[k + 1] = s[ns - 2]
    return y


def series_filter(x: np.ndarray, fn: float, zeta: float, dt: float, hold: str = "foh",
                  lag: float = 0.0, second: tuple[float, float] | None = None) -> np.ndarray:
    """Pass ``x`` through the unit-DC-gain second-order low-pass (fn Hz, damping ζ), at rest at ``x[0]``.

    ``hold='foh'``: ``s_{k+1} = Φ s_k + Γ1 x_k + Γ2 (x_{k+1} − x_k)`` for the state s = (y, ẏ), exact when x is
    linear between samples; ``hold='zoh'``: ``s_{k+1} = Φ s_k + Γ x_{k+1}``, exact when x_{k+1} is held over
    the period that ends at sample k+1 (``lag`` > 0: the sensor samples ``lag`` periods after the hold starts,
    see :func:`zoh_matrices`; ``foh`` takes no lag). ``second = (fn2, zeta2)``: a second unit-DC-gain mode
    driven by the first, the cascade discretised as one system; the output is the second mode's displacement.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    if hold not in HOLDS:
        raise EffectError(f"dynamics.hold must be one of {', '.join(HOLDS)}, not {hold!r}")
    sec = None if second is None else (float(second[0]), float(second[1]))
    if hold == "zoh":
        phi, g1, g2 = zoh_matrices(float(fn), float(zeta), float(dt), float(lag), sec)
    else:
        phi, g1, g2 = _foh_matrices(float(fn), float(zeta), float(dt), sec)
    return _series_run(phi, g1, g2, x) if sec is None else _cascade_run(phi, g1, g2, x)


# ---------------------------------------------------------------------------------------------- feedback
@njit(cache=True, nogil=True, inline="always")
def _rhs(p: np.ndarray, uu: float, y: float, v: float, w: float) -> tuple[float, float, float]:
    wn = 2.0 * np.pi * p[0]
    acc = wn * wn * (p[2] * uu - (1.0 - p[3]) * y - w) - 2.0 * p[1] * wn * v
    dw = p[3] * v - p[4] * abs(v) * w - p[5] * v * abs(w)
    return v, acc, dw


@njit(cache=True, nogil=True)
def msd_bw_simulate(p: np.ndarray, ufine: np.ndarray, substeps: int, dt: float,
                    y0: float = 0.0, v0: float = 0.0, w0: float = 0.0) -> np.ndarray:
    """Integrate the mass-spring-damper with Bouc-Wen restoring force (RK4, ``substeps`` per sample).

    Parameters
    ----------
    p : ndarray, shape (6,)
        ``(fn, zeta, gain, share, bg, bd)``, see the module docstring.
    ufine : ndarray, shape (2·substeps·(n−1) + 1,)
        Input on the half-substep grid (RK4 needs the midpoints): ``ufine[2·substeps·k]`` is sample k.
    substeps : int
        RK4 steps per sample period.
    dt : float
        Sample period (s).
    y0, v0, w0 : float
        Initial displacement (m), velocity (m/s) and hysteretic displacement w = z/(k+α) (m).

    Returns
    -------
    ndarray, shape (n,)
        Displacement at the sample instants (m); non-finite if the parameters make it diverge.
    """
    m2 = 2 * substeps
    n = (ufine.size - 1) // m2 + 1
    h = dt / substeps
    out = np.empty(n)
    y, v, w = y0, v0, w0
    out[0] = y
    for k in range(n - 1):
        base = k * m2
        for j in range(substeps):
            i = base + 2 * j
            u0, um, u1 = ufine[i], ufine[i + 1], ufine[i + 2]
            k1y, k1v, k1w = _rhs(p, u0, y, v, w)
            k2y, k2v, k2w = _rhs(p, um, y + 0.5 * h * k1y, v + 0.5 * h * k1v, w + 0.5 * h * k1w)
            k3y, k3v, k3w = _rhs(p, um, y + 0.5 * h * k2y, v + 0.5 * h * k2v, w + 0.5 * h * k2w)
            k4y, k4v, k4w = _rhs(p, u1, y + h * k3y, v + h * k3v, w + h * k3w)
            y += h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
            w += h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
            # During holds the state decays exponentially into subnormal floats, where every operation is
            # ~100x slower (measured: 110 ms instead of 23 ms per 40k-sample run); 1e-200 m is nothing physical.
            if abs(v) < 1e-200:
                v = 0.0
            if abs(w) < 1e-200:
                w = 0.0
            if abs(y) < 1e-200:
                y = 0.0
        out[k + 1] = y
        if not np.isfinite(y):
            for r in range(k + 2, n):
                out[r] = np.nan
            break
    return out


def upsample(u: np.ndarray, factor: int, method: str = "linear") -> np.ndarray:
    """Input on a grid ``factor`` times finer (``(n−1)·factor + 1`` points, sample k at index ``k·factor``).

    ``linear`` interpolates between samples; ``fft`` is band-limited interpolation assuming the record is one
    or more whole periods of a periodic signal (exact for multisines).
    """
    u = np.ascontiguousarray(u, dtype=np.float64)
    n = u.size
    if factor == 1 or n < 2:
        return u.copy()
    if method == "linear":
        return np.interp(np.arange((n - 1) * factor + 1) / factor, np.arange(n), u)
    if method == "fft":
        U = np.fft.rfft(u)
        m = n * factor
        Uf = np.zeros(m // 2 + 1, dtype=complex)
        Uf[:U.size] = U
        if n % 2 == 0:  # split the Nyquist bin so the result stays real and exact
            Uf[n // 2] *= 0.5
        uf = np.fft.irfft(Uf, m) * factor
        return uf[: (n - 1) * factor + 1]
    raise EffectError(f"dynamics.interp must be 'linear' or 'fft', not {method!r}")
