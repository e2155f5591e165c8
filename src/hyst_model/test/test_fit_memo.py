"""FitMemo: a remembered result is the computed one (copied, so a caller cannot change it), computed once per
content, and the oldest is forgotten beyond the size."""
from __future__ import annotations

import numpy as np

from hyst_model.identify.memo import FitMemo, content_key


def test_get_or_computes_once_per_content_and_returns_copies():
    memo = FitMemo(2)
    calls = []

    def compute(a):
        calls.append(a)
        return (float(a.sum()), a * 2.0)

    a = np.arange(5.0)
    first = memo.get_or(content_key("x", a), lambda: compute(a))
    again = memo.get_or(content_key("x", a.copy()), lambda: compute(a))  # same content, another array
    assert len(calls) == 1 and memo.hits == 1
    assert again[0] == first[0] and np.array_equal(again[1], first[1])
    again[1][:] = -1.0  # the caller's copy: the remembered value is untouched
    assert np.array_equal(memo.get_or(content_key("x", a), lambda: compute(a))[1], a * 2.0)
    b, c = a + 1.0, a + 2.0
    memo.get_or(content_key("x", b), lambda: compute(b))
    memo.get_or(content_key("x", c), lambda: compute(c))  # size 2: a's entry is the oldest, forgotten
    memo.get_or(content_key("x", a), lambda: compute(a))
    assert len(calls) == 4
