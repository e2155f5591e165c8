"""Results of deterministic base fits, remembered by the exact content of what they were fitted on.

A diagnosis fits the base MBW alone, from its multi-start grid, on the input as a delay transforms it before every
rung and screen (:func:`hyst_model.diagnose.refit.refit`, through :class:`~hyst_model.identify.fast.FastFit`): 13
such fits of 3 distinct inputs, 7 of 31 s, on a 60k-sample record.
The fit is a pure function of the record, the windows, the model's configuration and the fitter's budget, so the
key is a digest of exactly those; a hit returns the very numbers a new fit would (same result, same evaluation
count reported), only sooner. Bounded (least recently used) and thread-safe.
"""
from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from typing import Any, Callable

import numpy as np

__all__ = ["FitMemo", "content_key"]


def content_key(*parts: Any) -> bytes:
    """Digest of arrays (dtype, shape and bytes), None, and anything else by its ``repr``."""
    h = hashlib.blake2b(digest_size=20)
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"array{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(p).encode())
        h.update(b"\x1f")
    return h.digest()


class FitMemo:
    """A small LRU map from :func:`content_key` digests to fit results (copied in and out)."""

    def __init__(self, size: int = 16) -> None:
        self.size = int(size)
        self._d: OrderedDict[bytes, tuple] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0

    def get(self, key: bytes) -> tuple | None:
        with self._lock:
            v = self._d.get(key)
            if v is None:
                return None
            self._d.move_to_end(key)
            self.hits += 1
            return tuple(x.copy() if isinstance(x, np.ndarray) else x for x in v)

    def put(self, key: bytes, value: tuple) -> None:
        with self._lock:
            self._d[key] = tuple(x.copy() if isinstance(x, np.ndarray) else x for x in value)
            self._d.move_to_end(key)
            while len(self._d) > self.size:
                self._d.popitem(last=False)

    def get_or(self, key: bytes, compute: Callable[[], tuple]) -> tuple:
        """The remembered value of ``key``, or ``compute()`` remembered under it (two threads missing the same
        key at once both compute; the results are equal, the fit being a pure function of the key's content)."""
        hit = self.get(key)
        if hit is not None:
            return hit
        value = compute()
        self.put(key, value)
        return value
