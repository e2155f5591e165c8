"""Rate: the thesis's own modification of Bouc-Wen (BW → MBW), as an effect on a ``bw`` base.

The discrete BW (3.19) has rate-independent shape coefficients; the MBW (3.20)–(3.21) makes them depend on the
input rate v_{u,k} = |u_k − u_{k−1}|: ζ = ζ1 + ζ2·v, ψ = ψ1 + ψ2·v, α = α1 + α2·v. On a ``bw`` base this effect
adds ζ2, ψ2, α2 (``rate.zeta2`` ...) and simulates the MBW recursion of :mod:`hyst_model.core.mbw` — so
``bw + rate`` is exactly ``mbw``. On an ``mbw`` base it would model the same physics twice and is refused.
"""
from __future__ import annotations

import numpy as np

from ..core.params import BOUNDS
from ..errors import EffectError
from ..model import Param
from .base import Effect
from .signals import rate_of, smooth

__all__ = ["Rate"]


class Rate(Effect):
    """Rate-dependent shape coefficients ζ2, ψ2, α2 of the MBW (3.21) added to a BW base (3.19)."""

    name = "rate"
    summary = "loop shape changes with input rate: the MBW terms ζ2, ψ2, α2 of (3.20)-(3.21)"
    physics = ("The loop gets wider and tilts as the input moves faster (dielectric and eddy-current losses), "
               "so a rate-independent Bouc-Wen fits slow motion but misses fast motion.")
    kind = "base"
    online_note = "rate terms of a Bouc-Wen base: the controllers invert the MBW, which has them built in"
    bases = ("bw",)

    def params(self):
        return tuple(Param(n, 0.0, BOUNDS[n][0], BOUNDS[n][1], "", f"MBW rate term {n} (3.21)")
                     for n in ("zeta2", "psi2", "alpha2"))

    def check(self, base, others):
        if getattr(base, "name", "") == "mbw":
            raise EffectError("effect 'rate' is already part of the mbw base (its zeta2, psi2, alpha2 terms); "
                              "test it on the bw base (hyst fit --model bw, hyst diagnose --base bw)")
        super().check(base, others)

    def apply(self, theta, t, u, inner):
        to_params = getattr(inner.model, "to_params", None)
        if to_params is None:
            raise EffectError("effect 'rate' needs the Bouc-Wen base model bw (hyst fit --model bw, "
                              "hyst diagnose --base bw)")
        p = to_params(inner.theta).replace(zeta2=float(theta[0]), psi2=float(theta[1]), alpha2=float(theta[2]))
        return p.simulate(u)

    def signature(self, t, u, residual, dt):
        ud = np.abs(rate_of(u, dt, smooth_seconds=5 * dt))
        moving = ud > 0.05 * (ud.max() if ud.size else 0.0)
        if moving.sum() < 20:
            return 0.0, "the input hardly moves, so rate dependence cannot be seen"
        env = np.sqrt(smooth(residual ** 2, max(1, int(round(0.05 / dt)))))
        thr = np.median(ud[moving])
        fast, slow = moving & (ud > thr), moving & (ud <= thr)
        ef, es = float(np.sqrt(np.mean(env[fast] ** 2))), float(np.sqrt(np.mean(env[slow] ** 2)))
        ratio = ef / es if es > 0 else 1.0
        score = float(np.clip((ratio - 1.0) / 3.0, 0.0, 1.0))
        return score, (f"the error grows with the input rate: {ratio:.2f}× larger where the input moves fast than "
                       "where it moves slowly → the loop shape is rate dependent")
