"""Is a fitted model one the controllers can use? Remark 4.1 and parameters that ended on their bounds.

The thesis's controllers invert the MBW model one step ahead ((4.11)–(4.16), (5.22)–(5.27)). Remark 4.1 requires
α1 < −|ψ1| and α2 < −|ψ2|: then μ stays positive and ν takes the sign of the numerator, so μ⁺/μ⁻ are selected
correctly. A fit may violate it (the real piezo record with the default split ends with ψ1, ψ2 on their bounds
and α2 > 0); hyst_control then floors μ (its ``mu_select``), which keeps the command finite but is no longer
the thesis's law. A parameter that ends on its bound means the optimum lies outside the search box (or the
data do not determine it): the fit is not to be trusted without a look. Both are reported, never silent.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["Admissibility", "check_admissible"]


@dataclass
class Admissibility:
    """What :func:`check_admissible` found (``hyst fit --json``: ``admissibility``)."""

    remark_4_1: bool | None                 # None: the model has no MBW rate terms to check
    violations: list = field(default_factory=list)
    at_bounds: list = field(default_factory=list)
    controllers: str = ""                   # one sentence: can DPPC/DMRAC use it, and how

    def to_json(self) -> dict:
        return asdict(self)

    @property
    def clean(self) -> bool:
        return self.remark_4_1 is not False and not self.at_bounds


def check_admissible(model, theta, rel: float = 1e-6) -> Admissibility:
    """Check a fitted model (:class:`hyst_model.model.Model` and its packed θ).

    Parameters
    ----------
    rel : float
        A parameter within ``rel`` × (upper − lower) of a bound counts as on it.
    """
    theta = np.asarray(theta, dtype=np.float64)
    names = list(model.names)
    lo, hi = model.bounds
    width = np.where(np.isfinite(hi - lo), hi - lo, np.abs(theta) + 1.0)
    at = [f"{n} = {v:.6g} (on its {'lower' if v - lo[i] <= rel * width[i] else 'upper'} bound)"
          for i, (n, v) in enumerate(zip(names, theta))
          if (np.isfinite(lo[i]) and v - lo[i] <= rel * width[i]) or (np.isfinite(hi[i]) and hi[i] - v <= rel * width[i])]
    vals = dict(zip(names, theta))
    pairs = [(a, p) for a, p in (("alpha1", "psi1"), ("alpha2", "psi2")) if a in vals and p in vals]
    if not pairs:
        return Admissibility(None, [], at, "no MBW rate terms: Remark 4.1 does not apply")
    bad = [f"{a} = {vals[a]:.4g} is not < −|{p}| = {-abs(vals[p]):.4g}" for a, p in pairs
           if not vals[a] < -abs(vals[p])]
    basic = []
    if "zeta1" in vals and not vals["zeta1"] > 0:
        basic.append("zeta1 must be > 0 (Assumption 4.1)")
    for d in ("delta1", "delta2"):
        if d in vals and not 0 < vals[d] < 1:
            basic.append(f"{d} must be in (0, 1) (Theorems 4.1, 5.1)")
    if basic:
        verdict = "the controllers refuse this model: " + "; ".join(basic)
    elif bad:
        verdict = ("the controllers can run it, but with μ floored where it changes sign (Remark 4.1 violated): "
                   "not the thesis's law; refit with more excitation or check the parameters on their bounds")
    else:
        verdict = "the controllers can use it (Remark 4.1 holds: μ stays positive)"
    return Admissibility(not bad, bad, at, verdict)
