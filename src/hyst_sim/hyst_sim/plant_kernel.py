"""The plant's compiled per-sample loop and the layout of its packed settings/state arrays (split from plant.py).

See :mod:`hyst_sim.plant` for the signal chain and the end stops; this module holds only what numba compiles.
"""
from __future__ import annotations

import math

from numba import njit

from hyst_model.core import mbw_step

from hyst_common.limits import limit_step

from .truth_effects import asymmetry_kernel, creep_kernel, dynamics_kernel, saturation_kernel

#: The one range-and-slew limiter (:func:`hyst_common.limits.limit_step`), compiled for the loop below: the
#: simulated amplifier's clamp. Its wrapper in the loop makes any non-finite command (±inf too) hold the voltage
#: applied one sample earlier, flagged, as an amplifier ignores a corrupted setpoint.
clip_kernel = njit(cache=True)(limit_step)

# Indices into the packed float settings (_F) and state (_S) arrays of the compiled loop.
(F_US, F_YS, F_OFF, F_VMIN, F_VMAX, F_STEP, F_SUB, F_ASYM, F_XMID, F_HALF, F_CREEP, F_SAT, F_SATLO, F_SATHI,
 F_SATW, F_DYN, F_DR, F_DA, F_DW, F_DQ, F_NOISE, F_QUANT, F_DT, F_DELAY, F_YSTOPLO, F_YSTOPHI) = range(26)
N_F = 26
(S_Y, S_UM, S_UA, S_T, S_DRIFT, S_DT_T, S_DIDX, S_XQ, S_X) = range(9)


@njit(cache=True)
def _plant_loop(u_cmd, p, f, st, creep_a, creep_c, phi, gam, dz, dbuf, normals, out_y, out_u, out_f, out_x):
    """Advance the plant over ``u_cmd`` (V); states are updated in place (see the module signal chain)."""
    n_delay = int(f[F_DELAY])
    n_sub = int(f[F_SUB])
    for k in range(u_cmd.shape[0]):
        uc = u_cmd[k]
        if not math.isfinite(uc):  # ±inf too: held (limit_step saturates ±inf, holds NaN)
            uc = math.nan
        ua, flags = clip_kernel(uc, f[F_VMIN], f[F_VMAX], st[S_UA], f[F_STEP])
        st[S_UA] = ua
        ue = ua
        if n_delay > 0:
            i = int(st[S_DIDX])
            ue = dbuf[i]
            dbuf[i] = ua
            st[S_DIDX] = (i + 1) % n_delay
        um = ue / f[F_US]
        y = st[S_Y]
        up = st[S_UM]
        for _ in range(n_sub):
            y = mbw_step(p, y, um, up)
            up = um
        # The stage cannot leave its travel. A non-finite state is a numerical break, not physics: it is left
        # to _advance, which raises SimError so the node resets instead of publishing a stop position.
        if y < f[F_YSTOPLO] and math.isfinite(y):
            y = f[F_YSTOPLO]
            flags |= 8
        elif y > f[F_YSTOPHI] and math.isfinite(y):
            y = f[F_YSTOPHI]
            flags |= 8
        st[S_Y] = y
        st[S_UM] = um
        x = f[F_YS] * y + f[F_OFF]
        if f[F_ASYM] != 0.0:
            x = asymmetry_kernel(x, f[F_ASYM], f[F_XMID], f[F_HALF])
        st[S_XQ] = x
        if f[F_CREEP] != 0.0:
            x = creep_kernel(x, creep_c, creep_a, f[F_CREEP])
        if f[F_SAT] != 0.0:
            x = saturation_kernel(x, f[F_SATLO], f[F_SATHI], f[F_SATW])
        if f[F_DYN] != 0.0:
            x = dynamics_kernel(dz, phi, gam, x)
            # the stops hold the stage itself, after its resonance too (a 350 Hz mode driven at resonance swung
            # to -67..+73 µm on a 30 µm stroke with the stops only on the hysteresis)
            a = f[F_YS] * f[F_YSTOPLO] + f[F_OFF]
            b = f[F_YS] * f[F_YSTOPHI] + f[F_OFF]
            lo, hi = min(a, b), max(a, b)
            if x < lo or x > hi:  # the stage stops at the stop (an inelastic impact: the mode's energy is gone)
                x = lo if x < lo else hi
                dz[0] = x
                dz[1] = 0.0
                flags |= 8
        st[S_X] = x
        ym = x
        if f[F_DR] != 0.0:
            t0 = st[S_DT_T]
            t1 = t0 + f[F_DT]
            st[S_DRIFT] += (f[F_DR] * f[F_DT] + f[F_DA] * (math.sin(f[F_DW] * t1) - math.sin(f[F_DW] * t0))
                            + f[F_DQ] * normals[k, 1])
            st[S_DT_T] = t1
            ym += st[S_DRIFT]
        if f[F_NOISE] != 0.0:
            ym += f[F_NOISE] * normals[k, 0]
        if f[F_QUANT] != 0.0:
            ym = f[F_QUANT] * math.floor(ym / f[F_QUANT] + 0.5)
        st[S_T] += f[F_DT]
        out_y[k] = ym
        out_u[k] = ua
        out_f[k] = flags
        out_x[k] = x
