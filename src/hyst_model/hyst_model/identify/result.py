"""Fit results and the train/validation split shared by every estimator.

The split
---------
Every estimator simulates the model in free run (simulation mode, as the thesis's RMSE (3.26) and the Bouc-Wen
benchmark define it) **from rest at the start of the record**, and scores two windows of that one simulation:

* ``split = f`` (float, default 0.25): the last ``f`` of the samples are the validation window, the rest train.
* ``split = (t0, t1)`` (seconds): train on ``t0 <= t < t1``, validate on ``t >= t1`` (e.g. "the first three
  cycles"). Samples before ``t0`` are simulated but not scored, so the model state carries through them.
* ``split = 0`` or ``None``: no hold-out; ``rmse`` is then the training RMSE and ``split_`` says so.
* ``split = mask`` (boolean array, one per sample, True = validation): interleaved hold-out blocks, e.g.
  :func:`block_mask` (what ``hyst diagnose`` uses). The whole record is simulated; held-out samples are
  simply not scored in training, so the fit never sees them, and validation covers every part of the
  excitation (a tail hold-out of a sweep holds out only its highest frequencies, which the model must then
  extrapolate to).

Training only simulates up to the end of the training window (and never scores masked samples), so held-out
samples never influence the fit (with a mask, starts see the held-out samples bridged linearly).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..errors import FitError

__all__ = ["Split", "make_split", "block_mask", "block_phase", "FitResult", "rmse"]


def rmse(a: np.ndarray) -> float:
    """Root mean square (3.26); NaN for an empty array."""
    a = np.asarray(a, dtype=np.float64)
    if not a.size:
        return float("nan")
    with np.errstate(over="ignore"):  # a diverging candidate's residual: inf is its RMSE, not a warning on stderr
        return float(np.sqrt(np.mean(a * a)))


@dataclass(frozen=True)
class Split:
    """Index windows of one record: train ``[train_start, train_stop)``, validation ``[val_start, val_stop)``.

    With ``val_mask`` (interleaved blocks) both windows span the record and the mask selects the samples.
    """

    train_start: int
    train_stop: int
    val_start: int
    val_stop: int
    description: str
    val_mask: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def has_validation(self) -> bool:
        return self.val_stop > self.val_start

    def train_index(self) -> np.ndarray | slice:
        """Indexer of the training samples (for the residual of a full-record simulation)."""
        if self.val_mask is not None:
            return ~self.val_mask
        return slice(self.train_start, self.train_stop)

    def val_index(self) -> np.ndarray | slice:
        """Indexer of the validation samples."""
        if self.val_mask is not None:
            return self.val_mask
        return slice(self.val_start, self.val_stop)


def block_mask(n: int, fraction: float = 0.25, blocks: int = 8, u: np.ndarray | None = None) -> np.ndarray:
    """Validation mask of ``blocks`` interleaved blocks holding ``fraction`` of ``n`` samples.

    Block j is the last ``fraction`` of the j-th of ``blocks`` equal segments, so the first samples (the start
    from rest) always train and the record's tail is validated as with a tail split.

    With the input ``u``, the blocks are shifted together (by :func:`block_phase`) where that grid would give the
    validation less than half or more than twice its share of the input's changes. A record that moves in a few
    events (steps with holds) can otherwise have every event in training: generated GMA stage 1100087 (8 steps,
    a lightly damped mode ringing after each) had none in a validation block, so the base validated at 1.02× the
    noise floor while its training error was 10.6× and no effect could improve validation. Records whose input
    moves throughout (sines, noise, sweeps, triangles) keep the unshifted grid.
    """
    if not 0.0 < fraction < 1.0 or blocks < 1:
        raise FitError(f"block_mask needs 0 < fraction < 1 and blocks >= 1, got {fraction}, {blocks}")
    shift = 0.0 if u is None else block_phase(np.asarray(u, dtype=np.float64), fraction, blocks)
    return _blocks(int(n), fraction, blocks, shift)


def _blocks(n: int, fraction: float, blocks: int, shift: float) -> np.ndarray:
    m = np.zeros(n, dtype=bool)
    edges = np.linspace(0, n, blocks + 1)
    for j in range(blocks):
        a, b = edges[j], edges[j + 1]
        m[int(round(b - fraction * (b - a) - shift)):int(round(b - shift))] = True
    return m


def block_phase(u: np.ndarray, fraction: float = 0.25, blocks: int = 8) -> float:
    """Samples by which :func:`block_mask` shifts its blocks earlier so they hold a fair share of ``u``'s changes.

    Each change |Δu| counts for the quarter block after it (what a step excites follows it). The unshifted grid
    is kept while the blocks hold between half and twice ``fraction`` of that activity; otherwise the shift, in
    half blocks up to half a segment (the record's first ``fraction`` of a segment always trains), whose share is
    closest to ``fraction`` (on a log scale; the smaller shift on a tie). Depends on the input only, never on the
    output, so the hold-out stays blind to what is fitted.
    """
    n = u.size
    if n == 0:
        return 0.0
    # Every fit of a diagnosis asks this of the same input (5 ms at 60k samples, mostly the smearing): the answer
    # for the last input is kept, keyed by its content (one tuple: read whole).
    key = (hashlib.blake2b(np.ascontiguousarray(u).tobytes(), digest_size=16).digest(), n, fraction, blocks)
    last = _LAST_PHASE[0]
    if last is not None and last[0] == key:
        return last[1]
    shift = _block_phase(u, fraction, blocks)
    _LAST_PHASE[0] = (key, shift)
    return shift


_LAST_PHASE: list = [None]  # one (key, shift) tuple


def _block_phase(u: np.ndarray, fraction: float, blocks: int) -> float:
    n = u.size
    a = np.abs(np.diff(u, prepend=u[0]))
    seg = n / blocks
    width = max(1, int(round(fraction * seg / 4)))
    act = np.convolve(a, np.ones(width))[:n]
    total = float(act.sum())
    if total <= 0.0:
        return 0.0

    def share(shift: float) -> float:
        return float(act[_blocks(n, fraction, blocks, shift)].sum()) / total

    if 0.5 * fraction <= share(0.0) <= 2.0 * fraction:
        return 0.0
    step = 0.5 * fraction * seg
    shifts = [k * step for k in range(int(np.floor((1.0 - 2.0 * fraction) * seg / step + 1e-9)) + 1)]
    miss = [abs(np.log(max(share(s), 1e-12) / fraction)) for s in shifts]
    return shifts[int(np.argmin(miss))]


def make_split(t: np.ndarray, split) -> Split:
    """Turn a ``split`` specification (see module docstring) into index windows for sample times ``t``."""
    n = int(np.asarray(t).size)
    if isinstance(split, np.ndarray) and split.dtype == bool:
        if split.shape != (n,):
            raise FitError(f"a validation mask needs one entry per sample ({n}), got shape {split.shape}")
        nv = int(split.sum())
        if n - nv < 20 or nv < 1:
            raise FitError(f"validation mask leaves {n - nv} training and {nv} validation samples")
        runs = int(np.count_nonzero(np.diff(split.astype(np.int8)) == 1) + (1 if split[0] else 0))
        return Split(0, n, 0, n, f"train on {n - nv} samples, validate on {nv} samples in {runs} interleaved "
                                 "blocks, free-run from rest at the record start", val_mask=split.copy())
    if split is None or (isinstance(split, (int, float)) and float(split) == 0.0):
        return Split(0, n, n, n, "no hold-out: validation RMSE equals training RMSE")
    if isinstance(split, (int, float)):
        f = float(split)
        if not 0.0 < f < 1.0:
            raise FitError(f"validation fraction must be in (0, 1), got {f}")
        k = int(round(n * (1.0 - f)))
        if k < 20 or n - k < 1:
            raise FitError(f"record too short ({n} samples) for a {f:.0%} hold-out")
        return Split(0, k, k, n, f"train on the first {1 - f:.0%} of the record ({k} samples), validate on the "
                                 f"last {f:.0%} ({n - k} samples), free-run from rest at the record start")
    try:
        t0, t1 = (float(x) for x in split)
    except (TypeError, ValueError):
        raise FitError(f"split must be a fraction or (t0, t1) in seconds, got {split!r}") from None
    t = np.asarray(t, dtype=np.float64)
    a = int(np.searchsorted(t, t0, side="left"))
    b = int(np.searchsorted(t, t1, side="left"))
    if b - a < 20:
        raise FitError(f"training window {t0:g}–{t1:g} s holds only {max(b - a, 0)} samples "
                       f"(record spans {t[0]:g}–{t[-1]:g} s)")
    desc = (f"train on {t0:g} <= t < {t1:g} s ({b - a} samples), validate on t >= {t1:g} s ({n - b} samples), "
            "free-run from rest at the record start")
    return Split(a, b, b, n, desc)


@dataclass
class FitResult:
    """Outcome of one identification.

    Attributes
    ----------
    model : str
        Model name (base + effects, e.g. ``mbw`` or ``mbw+creep``).
    method : str
        ``fast``, ``epso`` or ``lsq``.
    params : dict
        Fitted parameter values by name (SI units where they have one).
    theta : ndarray
        Packed parameters in the model's order.
    rmse_train : float
        RMSE (m) on the training window (3.26).
    rmse : float
        RMSE (m) on the validation window (the number to trust); equals ``rmse_train`` without a hold-out.
    seconds : float
        Wall time of the fit (s).
    n_evaluations : int
        Model simulations used (Jacobian evaluations count as one each).
    n_iterations : int
        Optimiser iterations (swarm generations, least-squares iterations).
    residuals : ndarray
        Measured minus simulated output (m) over the whole record (free run from rest).
    split : str
        How train/validation were chosen.
    cost : float
        Final training cost (RMSE, m).
    history : list of float
        Best training RMSE per iteration (EPSO) or per start (fast).
    validated : bool
        False when the split left no validation samples (``rmse`` is then the training RMSE).
    """

    model: str
    method: str
    params: dict
    theta: np.ndarray
    rmse_train: float
    rmse: float
    seconds: float
    n_evaluations: int
    n_iterations: int
    residuals: np.ndarray
    split: str
    cost: float = float("nan")
    history: list = field(default_factory=list)
    message: str = ""
    validated: bool = True

    def to_dict(self) -> dict:
        """JSON-friendly summary (no residual array)."""
        return {"model": self.model, "method": self.method, "rmse": self.rmse, "rmse_train": self.rmse_train,
                "seconds": self.seconds, "n_evaluations": int(self.n_evaluations),
                "n_iterations": int(self.n_iterations), "split": self.split, "params": dict(self.params),
                "message": self.message}
