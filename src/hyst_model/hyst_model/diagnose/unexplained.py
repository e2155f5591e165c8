"""What is left when no library effect explains a large error: loop shape, or something outside the library.

A diagnosis that finds no significant effect while the base model still errs far above the sensor noise must not
answer "none": the model is wrong, just not in a way the effect library names. This module says *how* it is
wrong from the residual alone, with a number the user can check:

* **loop shape** — the residual is mostly a rate-independent function of the input's history, learnt on one part
  of the held-out samples and predicting the other: either a stationary function of where the input is and where
  it is going (mean per input-level bin × direction, :func:`loop_shape_share`), or a Prandtl–Ishlinskii operator of
  the input plus a rescaling of the model's own output (:func:`operator_share`) — what another hysteresis leaves
  of the model (the Prandtl–Ishlinskii truths of accuracy seed 40: loop shape in 1 of 16 by the first alone, in 11
  of 16 with the second; a mid-record stiffness change stays outside, 10 of 10). The hysteresis loop itself is
  the wrong shape for the base model (another hysteresis; a dead zone or backlash in the input; a rate-dependent
  loop on ``--base bw``).
* **outside the library** — it is not such a function: it depends on time, history or a condition the record
  does not show (a load change, temperature, a second actuator, friction with stick-slip, ...).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..effects.operators import plays
from ..effects.signals import fmt_len

__all__ = ["UNEXPLAINED_FACTOR", "Unexplained", "loop_shape_share", "operator_share", "explain_unexplained",
           "PLAY_RADII"]

#: A base error at least this many times the noise floor is never "nothing missing": twice the floor is clearly
#: above it (the "none" verdict needs ≤ 1.25×), so with no significant effect the answer is "unexplained".
#: At 5× (the issue's minimum) an input dead zone or a stiffness change leaving 3-5× the noise was a bare "none"
#: on 5 of 32 generated outside-library records; no record without an effect had its base above 1.25×.
UNEXPLAINED_FACTOR = 2.0
#: Above this share of variance the residual is called a loop-shape error.
LOOP_SHARE = 0.5
#: Radii of the play operators of :func:`operator_share`, as fractions of the record's input range: the textbook
#: Prandtl–Ishlinskii discretisation, uniform on [0, half the range) (radius 0 is the input itself).
PLAY_RADII = np.arange(10) * 0.05
#: Ridge of :func:`operator_share`'s regression, relative to the unit-variance columns' Gram (keeps it solvable
#: where plays coincide, e.g. on a record that never reverses by more than a small radius).
OPERATOR_RIDGE = 1e-6


@dataclass
class Unexplained:
    """The part of the error no library effect explains (``hyst diagnose --json``: ``unexplained``)."""

    rmse: float
    over_noise: float
    loop_shape_share: float
    kind: str          # "loop shape" | "outside the library"
    evidence: str
    #: The two predictions behind ``loop_shape_share`` (their larger): input level × direction
    #: (:func:`loop_shape_share`), hysteresis operator of the input and the model's output (:func:`operator_share`).
    level_share: float = 0.0
    operator_share: float = 0.0

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
    return _explained_share(e[test], means[g[test]])


def _explained_share(actual: np.ndarray, pred: np.ndarray) -> float:
    """1 − (prediction error power / power) of ``actual`` about their means, clipped to [0, 1]; 0 when there is
    nothing to explain or the prediction is not finite."""
    et = actual - actual.mean()
    pred = pred - pred.mean()
    power = float(np.mean(et * et))
    if power <= 0.0 or not np.all(np.isfinite(pred)):
        return 0.0
    return float(np.clip(1.0 - np.mean((et - pred) ** 2) / power, 0.0, 1.0))


def operator_share(u: np.ndarray, e: np.ndarray, yhat: np.ndarray, idx: np.ndarray, train: np.ndarray) -> float:
    """Share of the residual on ``idx[~train]`` predicted by a Prandtl–Ishlinskii operator of the input plus a
    rescaling of the model's output, fitted on ``idx[train]``.

    Another rate-independent hysteresis ``H`` fitted by the model leaves ``e = H(u) − ŷ``: a weighted sum of play
    operators of the input (:data:`PLAY_RADII`, run over the whole record so each sample carries its history), its
    square (an even-order bow) and ``ŷ`` itself predicts it out of sample, whatever amplitudes the two parts of the
    record visit. A residual that depends on time — a load change, a trend — is not predicted. Regularised least
    squares on unit-variance columns (:data:`OPERATOR_RIDGE`); 1 − (prediction error power / residual power) on
    the other samples, clipped to [0, 1].

    Parameters
    ----------
    u, e, yhat : ndarray
        Input (V), residual (m) and the model's output (m) over the whole record.
    idx : ndarray of int
        The samples judged (the held-out ones), in time order.
    train : ndarray of bool
        Over ``idx``: where the operator is fitted; the share is measured on the rest.
    """
    u = np.ascontiguousarray(u, dtype=np.float64)
    idx = np.asarray(idx)
    train = np.asarray(train, dtype=bool)
    test = ~train
    span = float(np.ptp(u))
    if span <= 0 or train.sum() < 8 * PLAY_RADII.size or test.sum() < 8 * PLAY_RADII.size:
        return 0.0
    un = (u - u.min()) / span
    F = np.column_stack([plays(un, PLAY_RADII), un * un, np.asarray(yhat, dtype=np.float64)])[idx]
    ev = np.asarray(e, dtype=np.float64)[idx]
    A, b = F[train], ev[train]
    mu, sd = A.mean(axis=0), A.std(axis=0)
    sd[sd == 0] = 1.0
    A = (A - mu) / sd
    G = A.T @ A
    w = np.linalg.solve(G + OPERATOR_RIDGE * A.shape[0] * np.eye(G.shape[0]), A.T @ (b - b.mean()))
    return _explained_share(ev[test], ((F[test] - mu) / sd) @ w)


def explain_unexplained(u: np.ndarray, e: np.ndarray, yhat: np.ndarray, idx: np.ndarray, train: np.ndarray,
                        rmse: float, noise: float, base: str, tested: list[str]) -> Unexplained:
    """Describe the unexplained error of the final model on the validation samples.

    Parameters
    ----------
    u, e, yhat : ndarray
        Input (V), residual of the best model (m) and its output (m), over the whole record.
    idx : ndarray of int
        The held-out samples, in time order.
    train : ndarray of bool
        Over ``idx``: where the loop-shape functions are learnt (they are tested on the rest).
    rmse, noise : float
        Its RMS on validation and the sensor noise floor (m).
    base : str
        Base model name, for the advice.
    tested : list of str
        Effects that were tested and found wanting.
    """
    level = loop_shape_share(np.asarray(u)[idx], np.asarray(e)[idx], train)
    op = operator_share(u, e, yhat, idx, train)
    share = max(level, op)
    ratio = rmse / noise if noise > 0 else float("inf")
    head = (f"{fmt_len(rmse)} RMS on held-out data is {ratio:.0f}× the sensor noise floor ({fmt_len(noise)}) and "
            f"none of {', '.join(tested)} explains it significantly")
    by = ("a function of input level and direction" if level >= op else
          f"a Prandtl–Ishlinskii operator of the input (plays up to half its range) with the {base} output rescaled")
    if share >= LOOP_SHARE:
        kind = "loop shape"
        why = (f"{share:.0%} of the held-out error is predicted by {by}, learnt on the first half of the held-out "
               f"samples: the {base} loop is the wrong shape for this actuator (another hysteresis such as "
               f"Prandtl–Ishlinskii, a dead zone or backlash in the input, or more excitation of the loop's "
               f"extremes)")
    else:
        kind = "outside the library"
        why = (f"only {share:.0%} of the held-out error is predicted by a function of input level and direction or "
               "by a hysteresis operator of the input, learnt on the first half of the held-out samples: it depends "
               "on time, long history or a condition the record does not show (a load or stiffness change, "
               "temperature, stick-slip friction, ...) — something outside the effect library; "
               "hyst_model.effects.Effect lets you add it")
    return Unexplained(float(rmse), float(ratio), float(share), kind, f"{head}; {why}", float(level), float(op))
