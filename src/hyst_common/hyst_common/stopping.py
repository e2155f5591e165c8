"""How a node's process stops: a lock-free stop flag and a watchdog that bounds the way out.

:func:`hyst_common.node.run_node` turns SIGINT/SIGTERM into a flag its spin loop reads. Two ways that could still
leave a process that never exits, both guarded here:

- The handler must not take a lock. ``threading.Event.set`` takes the event's (non-reentrant) lock; a second
  signal landing while the first handler holds it would deadlock the main thread in its own handler. The flag
  here is a plain attribute.
- A hang inside the ROS client library (the spin call or the teardown: executor shutdown, ``destroy_node``,
  ``rclpy.try_shutdown``) keeps the main thread in C code, where no Python handler runs. One of 50 controller
  stops in one CI run did not exit within 30 s; it was not reproduced in 850 further stress stops (400 of the code
  before this module, 450 with it), so its place is not known. The watchdog thread learns of the signal from the
  C-level handler itself (``signal.set_wakeup_fd``: CPython writes the signal number to the socket before any
  Python code runs), so it sees the signal even if the main thread never returns to Python.

Phases of a run and the watchdog's limits: ``start`` (``rclpy.init`` and building the node: no limit, a signal
there ends the loop before it starts) → ``spin`` (leave the loop: ``grace`` s after the signal) → ``exit``
(the node's own ``on_exit``: flushing a bag, ramping the amplifier to its safe output; no limit, it has its own)
→ ``teardown`` (the ROS teardown: ``grace`` s) → ``done``. When a limit passes, the watchdog writes one line
naming the phase and the stacks of all threads (for a bug report) to stderr and ends the process with
``os._exit``: exit 1 if the loop never ended (``on_exit`` did not run), 0 if only the ROS teardown hung after the
node's own work finished (what the user asked for happened; the line says what did not).
"""
from __future__ import annotations

import faulthandler
import os
import signal
import socket
import sys
import threading
import time

__all__ = ["StopGuard", "GRACE_S"]

#: Seconds a stop may spend leaving the spin loop, and again in the ROS teardown, before the watchdog ends it.
#: Both normally take well under 1 s; the margin is for a loaded machine.
GRACE_S = 15.0

_LIMITED = ("spin", "teardown")


class StopGuard:
    """Signal flag plus shutdown watchdog for one run of a node (see the module docstring).

    Parameters
    ----------
    prog : str
        Program name for the watchdog's message.
    grace : float, optional
        Seconds allowed for each limited phase (``spin`` after a signal, ``teardown``); :data:`GRACE_S` as it is
        when the guard is made.
    install : bool
        Install the SIGINT/SIGTERM handlers and the wakeup socket (only possible in the main thread; without
        them the watchdog still bounds the teardown).
    """

    def __init__(self, prog: str, grace: float | None = None, install: bool = True) -> None:
        self.prog = prog
        self.grace = float(GRACE_S if grace is None else grace)
        self.stopped = False  # written by the signal handler: a plain attribute, no lock (see the docstring)
        self._phase = "start"
        self._cond = threading.Condition()
        self._rx, self._tx = socket.socketpair()
        self._tx.setblocking(False)
        self._previous: dict[int, object] = {}
        self._old_fd: int | None = None
        if install:
            self._old_fd = signal.set_wakeup_fd(self._tx.fileno(), warn_on_full_buffer=False)
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._on_signal)
        self._thread = threading.Thread(target=self._watch, name=f"{prog}-stop-watchdog", daemon=True)
        self._thread.start()

    def _on_signal(self, _signum: int, _frame: object) -> None:
        self.stopped = True

    def phase(self, name: str) -> None:
        """Enter phase ``name`` (``spin``, ``exit``, ``teardown`` or ``done``); ``teardown`` arms the watchdog."""
        with self._cond:
            self._phase = name
            self._cond.notify_all()
        if name in ("teardown", "done"):
            self._kick()

    def close(self, exiting: bool = False) -> None:
        """End the watchdog and restore the previous handlers and wakeup fd (the run is over).

        ``exiting``: the process ends next (a console script), so a stop signal is ignored from here instead of
        restored: one arriving while the interpreter exited gave exit code 130 after a clean run."""
        self.phase("done")
        self._thread.join(timeout=5.0)
        for sig, old in self._previous.items():
            signal.signal(sig, signal.SIG_IGN if exiting else old)  # type: ignore[arg-type]
        if self._old_fd is not None:
            signal.set_wakeup_fd(self._old_fd)
        self._rx.close()
        self._tx.close()

    def _kick(self) -> None:
        try:
            self._tx.send(b"\0")
        except OSError:  # full (a byte is already waiting) or closed: the watchdog is awake either way
            pass

    def _watch(self) -> None:
        # CPython writes the number of every signal that has a Python handler (a node's own SIGHUP, say): only a
        # stop signal, or our own kick (0) on teardown/done, arms the limits
        wake = {0, int(signal.SIGINT), int(signal.SIGTERM)}
        try:
            while self._rx.recv(1)[0] not in wake:
                pass
        except (OSError, IndexError):  # closed
            return
        with self._cond:
            while self._phase != "done":
                phase = self._phase
                if phase not in _LIMITED:  # on_exit: no limit of ours
                    self._cond.wait()
                    continue
                deadline = time.monotonic() + self.grace
                while self._phase == phase and time.monotonic() < deadline:
                    self._cond.wait(deadline - time.monotonic())
                if self._phase == phase:
                    self._give_up(phase)

    def _give_up(self, phase: str) -> None:
        what = ("did not leave its spin loop" if phase == "spin" else
                "finished its work but the ROS teardown did not return")
        try:
            print(f"{self.prog}: stopping: the process {what} within {self.grace:g} s; ending it "
                  "(stacks of its threads follow, for a bug report)", file=sys.stderr, flush=True)
            faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
            sys.stderr.flush()
            sys.stdout.flush()
        finally:
            os._exit(1 if phase == "spin" else 0)
