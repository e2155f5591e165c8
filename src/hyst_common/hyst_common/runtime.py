"""Process-level helpers for the nodes (rclpy-free, so they are tested without ROS): command-line handling that
leaves ROS arguments alone, stopping node processes, and real-time scheduling for the nodes that close a 1 kHz
loop.

Real-time scheduling
--------------------
A loop closed across processes at 1 kHz has 1 ms for sample → controller → command → amplifier; a command that
misses it acts one sample later, and DPPC/DMRAC/PID are tuned for one sample of delay. Under CPU load from
other work, ordinary (CFS) scheduling lets that work preempt the loop. ``rt_priority`` (1–98) puts every thread of the
process — the node's own and the middleware's receive threads, which carry each sample to the callbacks — and
every thread started afterwards under ``SCHED_FIFO`` at that priority, as ``ros2_control``'s controller manager
does for its loop thread: measured on the 2-core test machine with two
CPU-bound processes beside it, DPPC over driver + emulator tracked to 79–92 nm RMS with normal scheduling and
to 23–28 nm with ``rt_priority`` 40 (unloaded: 23–36 nm). It needs ``CAP_SYS_NICE`` or an ``rtprio`` limit
(``/etc/security/limits.conf``, e.g. ``@realtime - rtprio 98``); without them the node keeps normal scheduling
and says so. The loop threads block between samples, and the kernel's RT throttling
(``/proc/sys/kernel/sched_rt_runtime_us``) keeps a runaway thread from freezing the machine.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = ["Scheduling", "set_realtime", "RT_PRIORITY_MAX", "own_args", "stop_processes"]

#: Highest priority offered: 99 is left to the kernel's own watchdog threads.
RT_PRIORITY_MAX = 98


@dataclass(frozen=True)
class Scheduling:
    """What :func:`set_realtime` achieved: ``policy`` is ``"fifo"`` or ``"normal"``; ``note`` says why."""

    policy: str
    priority: int
    note: str

    def __str__(self) -> str:
        return f"SCHED_FIFO {self.priority}" if self.policy == "fifo" else f"normal ({self.note})"


def set_realtime(priority: int) -> Scheduling:
    """Run every thread of this process (and threads started later) under ``SCHED_FIFO`` at ``priority``.

    Parameters
    ----------
    priority : int
        0 keeps normal scheduling; 1–98 asks for real-time FIFO scheduling.

    Returns
    -------
    Scheduling
        The policy in force afterwards. Never raises for lack of permission or an OS without the call: the
        node then runs with normal scheduling, and the returned note says why.

    Raises
    ------
    ValueError
        ``priority`` outside 0–98.
    """
    priority = int(priority)
    if not 0 <= priority <= RT_PRIORITY_MAX:
        raise ValueError(f"rt_priority must be 0 (normal scheduling) or 1-{RT_PRIORITY_MAX}, not {priority}")
    if priority == 0:
        return Scheduling("normal", 0, "rt_priority 0")
    if not hasattr(os, "sched_setscheduler"):
        return Scheduling("normal", 0, "this OS has no SCHED_FIFO")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # this thread: new threads inherit
        for tid in _threads():  # those already running (the middleware's)
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
            except ProcessLookupError:  # ended meanwhile
                pass
    except PermissionError:
        return Scheduling("normal", 0, f"SCHED_FIFO {priority} refused: needs CAP_SYS_NICE or an rtprio limit")
    except OSError as err:
        return Scheduling("normal", 0, f"SCHED_FIFO {priority} failed: {err.strerror or err}")
    return Scheduling("fifo", priority, "")


def _threads() -> list[int]:
    """Thread ids of this process (Linux ``/proc``; empty elsewhere)."""
    try:
        return [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return []


def own_args(args: list[str] | None) -> list[str]:
    """The node's own command-line words: ``args`` (default ``sys.argv``) without the program name and without
    everything from ``--ros-args`` on, which belongs to ROS."""
    import sys
    argv = sys.argv[1:] if args is None else list(args)
    return argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv


def stop_processes(procs, grace: float = 10.0, sig: int | None = None) -> list[int]:
    """Stop node processes the way a user's Ctrl-C does, then kill what is left.

    Parameters
    ----------
    procs : iterable of subprocess.Popen
        Signalled all at once (``sig``, SIGINT by default: every hyst node's runner stops cleanly on it), then
        waited for one after another, each up to ``grace`` seconds before it is killed.
    grace : float
        Seconds each process may take to shut down (a driver ramps to its safe output, a recorder finalises).
    sig : int, optional
        The signal; ``signal.SIGTERM`` for processes that are not hyst nodes.

    Returns
    -------
    list of int
        The exit codes, in the order of ``procs`` (negative: killed by that signal).
    """
    import signal
    import subprocess

    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT if sig is None else sig)
    codes = []
    for p in procs:
        try:
            codes.append(p.wait(grace))
        except subprocess.TimeoutExpired:
            p.kill()
            codes.append(p.wait())
    return codes
