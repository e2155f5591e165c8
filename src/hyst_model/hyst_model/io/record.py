"""A measured input/output record in SI units, with the data checks every reader applies.

A :class:`Record` is what bags and CSV files become: sample times ``t`` (s), applied voltage ``u`` (V) and
displacement ``y`` (m), plus free-form metadata (source, topic, unit conversions). The hysteresis recursions are
per-sample, so the record must be regularly sampled: :meth:`Record.check` rejects non-finite rows, time going
backwards and gaps with one clear :class:`~hyst_model.errors.DataError`, and :meth:`Record.segments` /
:meth:`Record.longest_segment` let a caller keep the longest regularly sampled stretch instead.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError

__all__ = ["Record", "MIN_SAMPLES"]

#: Fewer samples than this cannot identify an eight-parameter model.
MIN_SAMPLES = 20


@dataclass
class Record:
    """Sampled input/output data in SI units.

    Attributes
    ----------
    t : ndarray
        Sample times (s), strictly increasing after :meth:`check`.
    u : ndarray
        Applied input (V).
    y : ndarray
        Measured output (m).
    meta : dict
        Provenance: ``source``, ``topic``, ``columns``, ``units``, ... (informative only).
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=np.float64).ravel()
        self.u = np.asarray(self.u, dtype=np.float64).ravel()
        self.y = np.asarray(self.y, dtype=np.float64).ravel()
        if not (self.t.size == self.u.size == self.y.size):
            raise DataError(f"t, u, y have different lengths ({self.t.size}, {self.u.size}, {self.y.size})")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def source(self) -> str:
        return str(self.meta.get("source", "<data>"))

    @property
    def dt(self) -> float:
        """Median sample period (s); NaN for fewer than two samples."""
        if self.t.size < 2:
            return float("nan")
        return float(np.median(np.diff(self.t)))

    def slice(self, start: int = 0, stop: int | None = None) -> "Record":
        """A copy of samples ``start:stop`` with the same metadata."""
        return Record(self.t[start:stop].copy(), self.u[start:stop].copy(), self.y[start:stop].copy(),
                      dict(self.meta))

    def between(self, t0: float = -np.inf, t1: float = np.inf) -> "Record":
        """A copy of the samples with ``t0 <= t < t1``."""
        m = (self.t >= t0) & (self.t < t1)
        return Record(self.t[m], self.u[m], self.y[m], dict(self.meta))

    # checks -----------------------------------------------------------------------------------------------
    def check(self, *, max_gap: float = 1.5, min_samples: int = MIN_SAMPLES) -> "Record":
        """Raise :class:`DataError` unless the record is usable for a per-sample model; return self.

        Parameters
        ----------
        max_gap : float
            Largest allowed step between stamps, in median sample periods. Steps above it are gaps (lost samples):
            a recursion run across them would see a jump that never happened.
        min_samples : int
            Minimum number of samples.
        """
        n = len(self)
        where = self.source
        if n == 0:
            raise DataError(f"{where}: no samples")
        bad = ~(np.isfinite(self.t) & np.isfinite(self.u) & np.isfinite(self.y))
        if bad.any():
            idx = np.flatnonzero(bad)
            raise DataError(f"{where}: {idx.size} row(s) with NaN/inf values (first at row {idx[0]}, "
                            f"t = {float(self.t[idx[0]]):g} s); clean or cut the data first")
        if n < min_samples:
            raise DataError(f"{where}: only {n} samples; at least {min_samples} are needed")
        d = np.diff(self.t)
        if (d <= 0).any():
            k = int(np.flatnonzero(d <= 0)[0])
            raise DataError(f"{where}: time stamps not strictly increasing at row {k + 1} "
                            f"(t={self.t[k]:.9g} then {self.t[k + 1]:.9g} s); repeated stamps from a lockstep "
                            "run are collapsed by --gaps auto")
        dt = float(np.median(d))
        gaps = np.flatnonzero(d > max_gap * dt)
        if gaps.size:
            k = int(gaps[0])
            raise DataError(f"{where}: {gaps.size} gap(s) in the time stamps (first after t={self.t[k]:.6f} s: "
                            f"{d[k] * 1e3:.3f} ms vs a {dt * 1e3:.3f} ms sample period); samples were lost — "
                            "--gaps auto bridges short gaps (input held) and keeps the longest regular segment "
                            "between long ones; --gaps longest keeps only that segment")
        return self

    def jitter(self) -> float:
        """Relative RMS deviation of the sample period from its median (0 for a perfect clock)."""
        if len(self) < 3:
            return 0.0
        d = np.diff(self.t)
        return float(np.sqrt(np.mean((d - np.median(d)) ** 2)) / np.median(d))

    def segments(self, *, max_gap: float = 1.5) -> list[tuple[int, int]]:
        """``(start, stop)`` index ranges of regularly sampled, finite stretches (stop exclusive)."""
        n = len(self)
        if n == 0:
            return []
        finite = np.isfinite(self.t) & np.isfinite(self.u) & np.isfinite(self.y)
        cuts = np.zeros(n, dtype=bool)
        cuts[~finite] = True
        d = np.diff(self.t)
        dfin = d[np.isfinite(d) & (d > 0)]
        dt = float(np.median(dfin)) if dfin.size else np.inf
        brk = np.zeros(n, dtype=bool)
        with np.errstate(invalid="ignore"):
            brk[1:] = ~((d > 0) & (d <= max_gap * dt))
        out: list[tuple[int, int]] = []
        start = None
        for k in range(n):
            if cuts[k]:
                if start is not None:
                    out.append((start, k))
                start = None
                continue
            if start is None:
                start = k
            elif brk[k]:
                out.append((start, k))
                start = k
        if start is not None:
            out.append((start, n))
        return out

    def longest_segment(self, *, max_gap: float = 1.5, by: str = "length") -> "Record":
        """The longest regular, finite stretch (metadata records how much was dropped).

        ``by="variation"`` keeps instead the stretch whose input varies most (sum of squared deviations of ``u``
        from its mean; ties by length): on a rig's record the longest stretch is often the rest after the
        excitation, which holds nothing to identify.
        """
        segs = self.segments(max_gap=max_gap)
        if not segs:
            raise DataError(f"{self.source}: no finite samples")
        if by == "variation":
            def score(s):
                u = self.u[s[0]:s[1]]
                return (float(np.sum((u - u.mean()) ** 2)), s[1] - s[0])
            a, b = max(segs, key=score)
        else:
            a, b = max(segs, key=lambda s: s[1] - s[0])
        r = self.slice(a, b)
        r.meta["segment"] = [int(a), int(b)]
        r.meta["dropped_samples"] = int(len(self) - (b - a))
        return r
