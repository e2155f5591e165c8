"""Candidates fitted side by side: the diagnosis stages' loops over effects as a deterministic parallel map.

Each candidate's screen or refit is independent of the others: it reads the record, the fitted base and the
configuration, and fits its own model. :func:`pmap` runs them on ``Setup.jobs`` threads (the compiled recursions
release the GIL; hyst runs BLAS single-threaded, :mod:`hyst_common.blas`). Every task gets its own copy of the
configuration (an effect's variants are tried by changing its own keys) and its progress lines are passed on in
the items' order, so the result and the output are those of the sequential loop whatever the thread count or
the load: the same copy-per-task path runs with ``jobs`` = 1.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from .setup import Setup

__all__ = ["pmap", "default_jobs", "MAX_JOBS"]

#: Threads at most by default: the candidates of a stage are six built-in effects at most.
MAX_JOBS = 6


def default_jobs() -> int:
    """The processors this process may run on, at most :data:`MAX_JOBS`."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        n = os.cpu_count() or 1
    return max(1, min(n, MAX_JOBS))

T = TypeVar("T")


class _Lines:
    """A task's progress lines, kept until they can be passed on in order."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, dict[str, Any]]] = []

    def __call__(self, msg: str, **kw: Any) -> None:
        self.lines.append((msg, kw))


def pmap(s: Setup, fn: Callable[[Setup, Any], T], items: Iterable[Any],
         cost: Callable[[Any], float] | None = None) -> list[T]:
    """``[fn(own, item) for item in items]``, where ``own`` is ``s`` with its own configuration and progress.

    ``cost(item)``: an estimate of a task's time; on several threads the costliest start first (a long task
    started last kept one thread busy alone). Only the order of work changes, never the result or the lines.
    An exception of a task is raised where the sequential loop would have raised it (after the lines of the
    tasks before it); tasks already started finish first.
    """
    items = list(items)

    def run(item: Any) -> tuple[T, _Lines]:
        lines = _Lines()
        return fn(replace(s, cfg=dict(s.cfg), say=lines), item), lines

    def flush(lines: _Lines) -> None:
        for msg, kw in lines.lines:
            s.say(msg, **kw)

    out: list[T] = []
    if s.jobs <= 1 or len(items) <= 1:
        for it in items:
            res, lines = run(it)
            flush(lines)
            out.append(res)
        return out
    start = list(range(len(items)))
    if cost is not None:
        c = [cost(it) for it in items]
        start.sort(key=lambda i: -c[i])
    with ThreadPoolExecutor(max_workers=min(s.jobs, len(items))) as ex:
        submitted = {i: ex.submit(run, items[i]) for i in start}
        futures = [submitted[i] for i in range(len(items))]
        for f in futures:
            res, lines = f.result()
            flush(lines)
            out.append(res)
    return out
