"""Ctrl-C while a node process is still starting: one line and exit 0, not a KeyboardInterrupt traceback.

A node's console script imports numpy, numba kernels and rclpy before its ``main`` can take over the signals
(:class:`hyst_common.stopping.StopGuard`); a SIGINT in that first half second ended in a 50-line traceback from
inside an import and exit 130. :func:`quiet_start` (run when ``hyst_common`` is imported, first by every hyst
package) covers that window in hyst's own executables only — a process whose ``argv[0]`` is a ``hyst_*``
console script, on its main thread, with Python's default handler still in place: a library user's interpreter,
``hyst`` itself and the tests keep theirs. The runner (:func:`hyst_common.node.run_node`) and the executables
with their own loop call :func:`end_quiet_start` as they take over.
"""
from __future__ import annotations

import os
import signal
import sys
import threading

__all__ = ["quiet_start", "end_quiet_start"]

_installed = False


def _on_interrupt(_signum: int, _frame: object) -> None:
    name = os.path.basename(sys.argv[0]) if sys.argv else "hyst"
    print(f"{name}: interrupted while starting; nothing was running", file=sys.stderr, flush=True)
    raise SystemExit(0)


def quiet_start() -> bool:
    """Install the start-up SIGINT handler where it applies (see the module docstring); True when installed."""
    global _installed
    name = os.path.basename(sys.argv[0]) if sys.argv else ""
    if _installed or not name.startswith("hyst_") or threading.current_thread() is not threading.main_thread():
        return False
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return False
    signal.signal(signal.SIGINT, _on_interrupt)
    _installed = True
    return True


def end_quiet_start() -> None:
    """Python's default SIGINT handling again (KeyboardInterrupt), where :func:`quiet_start` replaced it."""
    global _installed
    if _installed and threading.current_thread() is threading.main_thread() \
            and signal.getsignal(signal.SIGINT) is _on_interrupt:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    _installed = False
