"""What is left when no library effect explains a large error: loop shape, or something outside the library.

A diagnosis that finds no significant effect while the base model still errs far above the sensor noise must not
answer "none": the model is wrong, just not in a way the effect library names. This module says *how* it is
wrong from the residual alone, with a number the user can check:

* **loop shape** — the residual is mostly a stationary function of where the input is and where it is going:
  learnt on the training samples (mean per input-level bin × direction), it predicts most of the held-out
  residual. The hysteresis loop itself
  is the wrong shape for the base model (another hysteresis, e.g. Prandtl–Ishlinskii; a dead zone or backlash in
  the input; a rate-dependent loop on ``--base bw``).
* **outside the library** — it is not such a function: it depends on time, history or a condition the record
  does not show (a load change, temperature, a second actuator, friction with stick-slip, ...).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..effects.signals import fmt_len

__all__ = ["UNEXPLAINED_FACTOR", "Unexplained", "loop_shape_share", "explain_unexplained"]

#: A base error at least this many times the noise floor is never "nothing missing": twice the floor is clearly
#: above it (the "none" verdict needs ≤ 1.25×), so with no significant effect the answer is "unexplained".
#: At 5× (the issue's minimum) an input dead zone or a stiffness change leaving 3-5× the noise was a bare "none"
#: on 5 of 32 generated outside-library records; no record without an effect had its base above 1.25×.
UNEXPLAINED_FACTOR = 2.0
#: Above this share of variance the residual is called a loop-shape error.
LOOP_SHARE = 0.5


@dataclass
class Unexplained:
    """The part of the error no library effect explains (``hyst diagnose --json``: ``unexplained``)."""

    rmse: float
    over_noise: float
    loop_shape_share: float
    kind: str          # "loop shape" | "outside the library"
    evidence: str

    def to_json(self) -> dict:
        return asdict(self)


def _groups(u: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Group index per sample: input level bin × direction of travel (holds keep the direction they arrived on)."""
    du = np.diff(u, prepend=u[0])
    sign = np.sign(du)
    moving = sign != 0
    if moving.any():
        last = np.maximum.accumulate(np.where(moving, np.arange(u.size), -1))
        last[last < 0] = int(np.flatnonzero(moving)[0])
        rising = sign[last] > 0
    else:
        rising = np.ones(u.size, dtype=bool)
    return np.searchsorted(edges, u) * 2 + rising


def loop_shape_share(u: np.ndarray, e: np.ndarray, train: np.ndarray, levels: int = 16) -> float:
    """Share of the held-out residual predicted by a function of input level and travel direction learnt on
    the training samples.

    The residual's mean per (input-level bin × rising/falling) group is learnt on ``train`` and used to predict
    the residual on the other samples; the share is 1 − (prediction error power / residual power) there,
    clipped to [0, 1]. An error of the loop's shape is a stationary function of where the input is and where it
    is going, so it is predicted out of sample; an error that depends on time (a slow trend, a load change) is
    not, even where it happens to correlate with the input inside one window.
    """
    u = np.asarray(u, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    train = np.asarray(train, dtype=bool)
    test = ~train
    if train.sum() < 8 * levels or test.sum() < 8 * levels:
        return 0.0
    edges = np.unique(np.quantile(u[train], np.linspace(0.0, 1.0, levels + 1)[1:-1]))
    g = _groups(u, edges)
    off = e[train].mean()
    ng = 2 * (edges.size + 1)
    counts = np.bincount(g[train], minlength=ng)
    sums = np.bincount(g[train], weights=e[train] - off, minlength=ng)
    means = np.divide(sums, counts, out=np.zeros_like(sums), where=counts >= 5)
    et = e[test] - e[test].mean()
    pred = means[g[test]]
    pred = pred - pred.mean()
    power = float(np.mean(et * et))
    if power <= 0.0:
        return 0.0
    return float(np.clip(1.0 - np.mean((et - pred) ** 2) / power, 0.0, 1.0))


def explain_unexplained(u: np.ndarray, e_val: np.ndarray, train: np.ndarray, rmse: float, noise: float,
                        base: str, tested: list[str]) -> Unexplained:
    """Describe the unexplained error of the final model on the validation samples.

    Parameters
    ----------
    u : ndarray
        Input over the samples of ``e_val`` (V).
    e_val : ndarray
        Residual of the best model (m), over the whole record.
    train : ndarray of bool
        Training samples (the loop-shape function is learnt there and tested on the rest).
    rmse, noise : float
        Its RMS on validation and the sensor noise floor (m).
    base : str
        Base model name, for the advice.
    tested : list of str
        Effects that were tested and found wanting.
    """
    share = loop_shape_share(u, e_val, train)
    ratio = rmse / noise if noise > 0 else float("inf")
    head = (f"{fmt_len(rmse)} RMS on held-out data is {ratio:.0f}× the sensor noise floor ({fmt_len(noise)}) and "
            f"none of {', '.join(tested)} explains it significantly")
    if share >= LOOP_SHARE:
        kind = "loop shape"
        why = (f"{share:.0%} of the held-out error is predicted by a function of input level and direction learnt "
               f"on the training part: the "
               f"{base} loop is the wrong shape for this actuator (another hysteresis such as Prandtl–Ishlinskii, "
               f"a dead zone or backlash in the input, or more excitation of the loop's extremes)")
    else:
        kind = "outside the library"
        why = (f"only {share:.0%} of the held-out error is predicted by a function of input level and direction "
               "learnt on the training part: it depends on time, long history or a condition the record does not "
               "show (a load or stiffness change, temperature, stick-slip friction, ...) — something outside the "
               "effect library; hyst_model.effects.Effect lets you add it")
    return Unexplained(float(rmse), float(ratio), float(share), kind, f"{head}; {why}")
