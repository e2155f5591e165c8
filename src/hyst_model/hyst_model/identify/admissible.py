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

from hyst_common.blas import one_blas_thread

from ..core.bounded import DIVERGENCE_SPANS, probe_range
from ..errors import FitError
from ..model import Model
from .result import FitResult

__all__ = ["Admissibility", "check_admissible", "probe_bounded", "AdmissibleModel", "fit_admissible", "MARGIN",
           "REST_MARGIN",
           "outside", "constrain", "provenance", "constrained_summary", "require_remark",
           "DIVERGENCE_SPANS"]

@dataclass
class Admissibility:
    """What :func:`check_admissible` found (``hyst fit --json``: ``admissibility``)."""

    remark_4_1: bool | None                 # None: the model has no MBW rate terms to check
    violations: list = field(default_factory=list)
    at_bounds: list = field(default_factory=list)
    controllers: str = ""                   # one sentence: can DPPC/DMRAC use it, and how
    bounded: bool | None = None             # None: not probed (no record given)
    divergence: str = ""                    # what the probe found when it is not bounded

    def to_json(self) -> dict:
        return asdict(self)

    @property
    def clean(self) -> bool:
        return self.remark_4_1 is not False and not self.at_bounds and self.bounded is not False


def probe_bounded(model, theta, u: np.ndarray, y: np.ndarray, dt: float, n: int = 8000) -> tuple[bool, str]:
    """Whether ``model`` stays bounded on inputs within the range of the record ``(u, y)`` it was fitted to.

    The probes of :func:`hyst_model.core.bounded.probe_range` within [min u, max u], judged against the record's
    output range, with steps in one sample (a record's own slew says nothing of what a controller will command;
    the controller node probes again with its own limits). A fit can be accurate on its record and unstable off
    it: the fitted MBW of generated records diverged on a fresh record of the same stage (to 1e12–1e57 m) while
    fitting its own; nothing said so.
    Returns ``(bounded, what the worst probe did)``.
    """
    u, y = np.asarray(u, dtype=np.float64), np.asarray(y, dtype=np.float64)
    mid = 0.5 * (float(np.max(y)) + float(np.min(y)))
    return probe_range(lambda uu: model.simulate(theta, np.arange(uu.size) * dt, uu), float(np.min(u)),
                       float(np.max(u)), float(np.ptp(y)), mid, n,
                       names=("the record's output range", "inputs the record spans"))


def check_admissible(model, theta, rel: float = 1e-6, record: tuple | None = None) -> Admissibility:
    """Check a fitted model (:class:`hyst_model.model.Model` and its packed θ).

    Parameters
    ----------
    rel : float
        A parameter within ``rel`` × (upper − lower) of a bound counts as on it.
    record : (t, u, y), optional
        The record it was fitted to: the model is then also probed for divergence within its input range
        (:func:`probe_bounded`); a model that diverges there is reported as unstable off its record.
    """
    adm = _check_parameters(model, theta, rel)
    if record is not None:
        t, u, y = (np.asarray(a, dtype=np.float64) for a in record)
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        adm.bounded, adm.divergence = probe_bounded(model, theta, u, y, dt)
        if not adm.bounded:
            vals = dict(zip(model.names, np.asarray(theta, dtype=np.float64)))
            hint = ("; hyst fit --admissible keeps the rate terms passive (ψ ≥ 0) and avoids this"
                    if _active_rate(vals) else "")
            adm.controllers = (f"unstable off its record — {adm.divergence}{hint}; trust it (and a controller built "
                               f"on it) only on inputs like the record's; {adm.controllers}")
    return adm


def _check_parameters(model, theta, rel: float) -> Admissibility:
    """Remark 4.1, Assumption 4.1 and parameters on their bounds (:func:`check_admissible`)."""
    theta = np.asarray(theta, dtype=np.float64)
    names = list(model.names)
    lo, hi = model.bounds
    width = np.where(np.isfinite(hi - lo), hi - lo, np.abs(theta) + 1.0)
    at = [f"{n} = {v:.6g} (on its {'lower' if v - lo[i] <= rel * width[i] else 'upper'} bound)"
          for i, (n, v) in enumerate(zip(names, theta))
          if (np.isfinite(lo[i]) and v - lo[i] <= rel * width[i])
          or (np.isfinite(hi[i]) and hi[i] - v <= rel * width[i])]
    vals = dict(zip(names, theta))
    # a memory held at the constrained fit's own limit (REST_MARGIN below 1) is reported as a bound would be
    at += [f"{d} = {vals[d]:.7g} (within {1.5 * REST_MARGIN:.2g} of 1, where the constrained fit holds it: the data "
           "push it to 1)"
           for d in ("delta1", "delta2") if d in vals and 1.0 - 1.5 * REST_MARGIN <= vals[d] < 1.0 - rel * 0.5]
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
                   "not the thesis's law; refit with --admissible (hyst fit or hyst diagnose: Remark 4.1 held by "
                   "construction, with the free fit's error beside it), with more excitation, or check the "
                   "parameters on their bounds")
    else:
        verdict = "the controllers can use it (Remark 4.1 holds: μ stays positive)"
    return Admissibility(not bad, bad, at, verdict)


#: Smallest margin α + |ψ| < −MARGIN the constrained fit keeps (in the model's normalised units).
MARGIN = 1e-4
#: Smallest rest contraction 1 − a the constrained fit keeps (per sample): a held input settles within about
#: 1/REST_MARGIN samples. Also how far δ2 stays below 1 (the controllers need δ1, δ2 in (0, 1)).
REST_MARGIN = 1e-6


class AdmissibleModel(Model):
    """A model reparameterised so that Remark 4.1 holds by construction: α_i = −|ψ_i| − m_i, m_i ≥ MARGIN.

    Same parameters as the wrapped model except each ``alpha<i>`` with a ``psi<i>`` partner is replaced by
    ``alpha<i>_margin`` (m_i). :meth:`inner` maps a packed θ' back to the wrapped model's θ, so the result is an
    ordinary model of the same name (params files, controllers unchanged). Works for MBW/BW bases and composed
    models on them (the names are the same there).

    With ``u_max`` (the largest |u| of the record, V) δ1 is replaced by ``delta1_margin`` (d1) too, so that a
    held input has a rest state everywhere in the record's range. At rest (3.21) is y ← a·y + ζ1·ν with
    ν = (1 − δ2)·u and, once y has the sign of ν, a = δ1 − ψ1|ν| − α1|ν| = δ1 + m1·|ν|: Remark 4.1 (m1 > 0)
    makes the hysteresis term *expand* the state, so it needs δ1 < 1 − m1·(1 − δ2)·U (U = u_max / u_scale), or
    the output grows without bound under a held input. δ1 = 1 − d1 − m1·(1 − δ2)·U, d1 ≥ :data:`REST_MARGIN`.
    (The real piezo record's diagnosed model, refitted under Remark 4.1 without it, ended on δ1 = 1 and diverged
    off its record; the controllers refuse δ1 = 1.)
    """

    def __init__(self, model, u_max: float | None = None):
        from ..model import Param
        self.model = model
        self.name = model.name
        names = list(model.names)
        self.pairs = [(names.index(a), names.index(p)) for a, p in (("alpha1", "psi1"), ("alpha2", "psi2"))
                      if a in names and p in names]
        if not self.pairs:
            raise ValueError("no alpha/psi pair to constrain (Remark 4.1 applies to MBW and BW bases)")
        lo, _ = model.bounds
        ps = list(model.params())
        for ia, ip in self.pairs:
            p, q = ps[ia], ps[ip]
            top = max(-float(lo[ia]), MARGIN * 10)  # α ≥ its lower bound ⇒ m ≤ −lo − |ψ| ≤ −lo
            # |ψ| < −lo(α): otherwise no α within its bounds is below −|ψ| (α is clipped at lo(α) in inner())
            lim = top - MARGIN
            # ψ ≥ 0: with α < −|ψ| the loading branch grows y by (1 + |ψ + α|·|ν|) per sample and unloading shrinks
            # it by (1 − (ψ − α)·|ν|); their product exceeds 1 when ψ1 + ψ2·v < 0, so a ψ2 < 0 turns into a
            # runaway once the input moves faster than ψ1/|ψ2| per sample (the real piezo fit: ψ2 = −1 with
            # ψ1 = 1e-5 — any step above 0.15 mV/sample). The thesis's own sets all have ψ ≥ 0.
            ps[ip] = Param(q.name, float(np.clip(q.default, 0.0, lim)), max(q.lower, 0.0), min(q.upper, lim),
                           q.unit, q.doc)
            ps[ia] = Param(f"{p.name}_margin", max(MARGIN, -p.default - abs(ps[ip].default)), MARGIN, top, p.unit,
                           f"how far {p.name} stays below −|{ps[ip].name}| (Remark 4.1)")
        self.rest: tuple[int, int, int, int, float] | None = None  # (δ1, δ2, α1, ψ1 indices, U)
        u_scale = float(model.config().get("u_scale", 1.0) or 1.0)
        if (u_max is not None and "delta1" in names and "delta2" in names and "alpha1" in names
                and "psi1" in names):
            i1, i2 = names.index("delta1"), names.index("delta2")
            d1, d2 = ps[i1], ps[i2]
            ps[i2] = Param(d2.name, min(d2.default, 1.0 - REST_MARGIN), d2.lower, min(d2.upper, 1.0 - REST_MARGIN),
                           d2.unit, d2.doc)
            ps[i1] = Param("delta1_margin", max(REST_MARGIN, 1.0 - d1.default), REST_MARGIN, 1.0 - d1.lower,
                           d1.unit, "how far delta1 stays below the largest value with a rest state over the "
                           "record's input range (1 − m1·(1 − delta2)·u_max/u_scale)")
            self.rest = (i1, i2, names.index("alpha1"), names.index("psi1"), abs(float(u_max)) / u_scale)
        self._params = tuple(ps)

    def params(self):
        return self._params

    def config(self):
        return self.model.config()

    def inner(self, theta_c) -> np.ndarray:
        """θ of the wrapped model (α from ψ and the margin, clipped to α's own lower bound)."""
        th = np.asarray(theta_c, dtype=np.float64).copy()
        lo, hi = self.model.bounds
        for ia, ip in self.pairs:
            th[ia] = max(-abs(th[ip]) - th[ia], lo[ia])
        if self.rest is not None:
            i1, i2, ia, ip, big_u = self.rest
            m1 = -th[ia] - abs(th[ip])  # α1's margin as applied (after the clip above)
            k = (1.0 - th[i2]) * big_u
            delta1 = 1.0 - th[i1] - m1 * k
            if delta1 < lo[i1] and k > 0:
                # δ1 at the bottom of its box: the rest state is kept by a smaller α1 margin instead (continuous
                # at the switch; the floor MARGIN leaves a < 1 unless (1 − δ2)·U exceeds ~5000)
                m1 = max((1.0 - th[i1] - lo[i1]) / k, MARGIN)
                th[ia] = max(-abs(th[ip]) - m1, lo[ia])
                delta1 = lo[i1]
            th[i1] = min(delta1, hi[i1])
        return th

    def outer(self, theta) -> np.ndarray:
        """The nearest admissible θ' for a wrapped θ (margins at least :data:`MARGIN`)."""
        th = np.asarray(theta, dtype=np.float64).copy()
        for ia, ip in self.pairs:
            th[ia] = max(-th[ia] - abs(th[ip]), MARGIN)
        lo, hi = self.bounds
        th = np.clip(th, lo, hi)
        if self.rest is not None:
            i1, i2, ia, _, big_u = self.rest
            th[i1] = max(1.0 - float(theta[i1]) - th[ia] * (1.0 - th[i2]) * big_u, REST_MARGIN)
            th = np.clip(th, lo, hi)
        return th

    def simulate(self, theta_c, t, u):
        return self.model.simulate(self.inner(theta_c), t, u)


def outside(model, theta) -> bool:
    """Whether θ leaves the set :class:`AdmissibleModel` fits in: Remark 4.1 violated, or a rate term ψ < 0."""
    vals = dict(zip(model.names, np.asarray(theta, dtype=np.float64)))
    return (any(a in vals and p in vals and not vals[a] < -abs(vals[p]) for a, p in (("alpha1", "psi1"),
                                                                                      ("alpha2", "psi2")))
            or _active_rate(vals))


def _active_rate(vals: dict) -> bool:
    """A rate term ψ < 0: anti-damping that grows with the input's speed (see :class:`AdmissibleModel`)."""
    return any(vals.get(p, 0.0) < 0 for p in ("psi1", "psi2"))


@one_blas_thread
def constrain(model, t, u, y, theta, split) -> FitResult | None:
    """``hyst fit --admissible``, ``hyst diagnose --admissible`` and the ident node's ``admissible``: None when θ
    (a free fit of ``model``) is already admissible, else the constrained refit (:func:`fit_admissible`) as a
    FitResult of ``model`` (θ, params, validation and training RMSE on the same ``split``: a fraction, a split
    name or a boolean validation mask)."""
    if not outside(model, theta):
        return None
    from .result import make_split
    theta_c, res = fit_admissible(model, t, u, y, theta, split)
    res.params, res.theta = model.unpack(theta_c), theta_c
    e = np.asarray(y, dtype=np.float64) - model.simulate(theta_c, t, u)
    sp = make_split(t, split)
    res.rmse = float(np.sqrt(np.mean(e[sp.val_index()] ** 2))) if sp.has_validation else res.rmse
    res.rmse_train = float(np.sqrt(np.mean(e[sp.train_index()] ** 2)))
    return res


def require_remark(adm: Admissibility, model_name: str, option: str = "--admissible") -> None:
    """Refuse a constrained fit of a model without α/ψ terms (``option`` names the setting the user gave)."""
    if adm.remark_4_1 is None:
        raise FitError(f"{option}: model {model_name} has no alpha/psi terms; Remark 4.1 does not apply")


def constrained_summary(free_rmse: float, free_violations: list[str], rmse: float) -> dict:
    """The ``constrained`` object of the JSON and the ident node's summary: what the free fit validated at, what it
    violated, and what the constrained one validates at (hyst fit, hyst diagnose and the ident node alike)."""
    return {"free_rmse": float(free_rmse), "free_violations": list(free_violations), "rmse": float(rmse)}


def provenance(free_rmse: float) -> str:
    """The params file's ``fit.admissible`` line for a constrained fit (hyst fit and hyst diagnose alike)."""
    return f"Remark 4.1 and passive rate terms (psi >= 0) enforced; the free fit validated at {free_rmse:.4g} m"


def fit_admissible(model, t, u, y, theta, split, max_nfev: int = 150):
    """Refit ``model`` from ``theta`` (a free fit) with Remark 4.1 and passive rate terms (ψ ≥ 0) enforced;
    returns (θ of ``model``, result).

    The free optimum is projected onto the admissible set (each α pushed below −|ψ| by at least the margin)
    and the output-error least squares continues from there in the reparameterised model
    (:class:`AdmissibleModel`), so the answer always satisfies α_i < −|ψ_i|; its validation RMSE is what the
    constraint costs on these data.
    """
    from . import fit
    am = AdmissibleModel(model, u_max=float(np.max(np.abs(u))))
    res = fit(am, t, u, y, method="fast", split=split, theta0=am.outer(theta), max_nfev=max_nfev)
    return am.inner(res.theta), res
