"""Jacobian of a composed model: the base's exact sensitivities carried through the effects around it.

A finite-difference Jacobian of ``base + effects`` simulates the whole structure once per parameter; the base
parameters are most of them (nine for the MBW), and each of those simulations runs the base recursion and every
effect. Here the base parameters' columns come from the base's own forward sensitivities
(:meth:`hyst_model.model.MBWModel.simulate_jac`, about two simulations' cost for all of them) on the input the base
actually sees (after the input-side effects, which do not depend on base parameters), carried outward through
each output-side effect by the chain rule (:meth:`push_through`). Only the effects' own parameters are stepped by
finite differences — cheap, since the composed model reuses its unchanged inner stages
(:class:`~hyst_model.effects.base.ComposedModel`).

Available when the base has ``simulate_jac`` and every effect is input- or output-side in the default form (no
``wrap``/``base`` kind, no overridden ``apply``), or says its ``apply`` is its ``output`` (``acts_on_output``: the
series mode): :attr:`ComposedModel.jac_available`. Otherwise the fitters fall
back to finite differences of the whole model, as before.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover - typing only
    from .base import ComposedModel, Effect

__all__ = ["jac_available", "composed_simulate_jac", "push_through"]

#: Relative signal perturbation of the directional differences in :func:`push_through` (the signal is in m; a
#: step of 1e-7 of its largest value keeps rounding near 1e-9 relative and the truncation of smooth maps below).
REL_STEP = 1e-7


def jac_available(model: "ComposedModel") -> bool:
    """Whether :func:`composed_simulate_jac` applies to ``model`` (see the module docstring)."""
    from .base import Effect
    return hasattr(model.base, "simulate_jac") and all(
        (e.kind in ("input", "output") and type(e).apply is Effect.apply) or _on_output(e) for e in model.effects)


def _on_output(effect: "Effect") -> bool:
    """An effect whose ``apply`` is its ``output`` on the inner output although it says otherwise (the series
    mode: ``acts_on_output``)."""
    return bool(getattr(effect, "acts_on_output", False))


def push_through(effect: "Effect", theta: np.ndarray, t: np.ndarray, u: np.ndarray, x: np.ndarray,
                 y: np.ndarray, J: np.ndarray) -> np.ndarray:
    """d y / d p for the columns ``J = d x / d p`` of an output effect's input ``x`` (its output is ``y``).

    An effect's own ``push(theta, t, u, x, y, J)`` if it has one (creep: its lag bank over all columns at once);
    exact for a linear operator (:attr:`Effect.linear`: the effect applied to each column); for an effect that
    acts sample by sample (:attr:`Effect.pointwise`) its derivative once, from one uniformly shifted evaluation;
    otherwise one directional difference per column.
    """
    exact = getattr(effect, "push", None)
    if exact is not None:
        return np.asarray(exact(theta, t, u, x, y, J), dtype=np.float64)
    scale = float(np.max(np.abs(x))) if x.size else 0.0
    h = REL_STEP * (scale if scale > 0 else 1e-9)
    out = np.empty_like(J)
    if getattr(effect, "linear", False):
        zero = effect.output(theta, t, u, np.zeros_like(x))  # the operator's own output at rest (zero if linear)
        for k in range(J.shape[1]):
            out[:, k] = effect.output(theta, t, u, np.ascontiguousarray(J[:, k])) - zero
        return out
    if getattr(effect, "pointwise", False):
        slope = (effect.output(theta, t, u, x + h) - y) / h
        return slope[:, None] * J
    for k in range(J.shape[1]):
        col = J[:, k]
        m = float(np.max(np.abs(col)))
        if m == 0.0:
            out[:, k] = 0.0
            continue
        s = h / m
        out[:, k] = (effect.output(theta, t, u, x + s * col) - y) / s
    return out


def composed_simulate_jac(model: "ComposedModel", theta: np.ndarray, t: np.ndarray, u: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Output (m) of ``model`` and its Jacobian d y / d θ, shape (n, len(θ)).

    Base columns: the base's sensitivities on its input, pushed through the output effects. Effect columns:
    forward differences with the step rule of :meth:`hyst_model.identify.base.TrainProblem.fd_residuals_jac`
    (stepping inward at an upper bound), outermost first so unchanged inner stages are reused.
    """
    with model.reusing_stages():
        return _simulate_jac(model, theta, t, u)


def _simulate_jac(model: "ComposedModel", theta: np.ndarray, t: np.ndarray, u: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    theta = np.asarray(theta, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    tb, tes = model.split(theta)
    y = np.asarray(model.simulate(theta, t, u), dtype=np.float64)  # also primes the reused stages
    J = np.zeros((y.size, theta.size))

    def sens(j: int, uu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output and base-parameter columns of the structure up to effect ``j`` (−1: the base alone)."""
        if j < 0:
            x, Jb = model.base.simulate_jac(tb, t, uu)  # type: ignore[attr-defined]  # jac_available checked it
            return np.asarray(x, dtype=np.float64), np.asarray(Jb, dtype=np.float64)
        e = model.effects[j]
        if e.kind == "input" and not _on_output(e):
            return sens(j - 1, np.asarray(e.input(tes[j], t, uu), dtype=np.float64))
        x, Jx = sens(j - 1, uu)
        yj = np.asarray(e.output(tes[j], t, uu, x), dtype=np.float64)
        return yj, push_through(e, tes[j], t, uu, x, yj, Jx)

    _, Jb = sens(len(model.effects) - 1, u)
    nb = tb.size
    J[:, :nb] = Jb
    lo, hi = model.bounds
    span = hi - lo
    for i in reversed(range(nb, theta.size)):
        h = 1e-6 * max(abs(theta[i]), 1e-3 * span[i] if np.isfinite(span[i]) else 1e-3, 1e-12)
        if theta[i] + h > hi[i]:
            h = -h
        tp = theta.copy()
        tp[i] += h
        J[:, i] = (np.asarray(model.simulate(tp, t, u), dtype=np.float64) - y) / h
    return y, J
