"""File modes for hyst's outputs: what ``open()`` would give under the user's umask.

hyst writes every output atomically through :func:`tempfile.mkstemp` (write, then rename or link), and mkstemp
creates files 0600 whatever the umask; the rename keeps that mode, so a params file or a report came out
unreadable to the group even with umask 022 — also after ``--force`` replaced a 0644 file. :func:`mkstemp_user`
is mkstemp with the mode a plain ``open(path, "w")`` would have given.
"""
from __future__ import annotations

import os
import tempfile

__all__ = ["user_umask", "mkstemp_user"]


def user_umask() -> int:
    """The process's umask, read without changing it where the OS allows (Linux ``/proc/self/status``)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    old = os.umask(0o022)          # portable fallback: set and restore at once
    os.umask(old)
    return old


def mkstemp_user(**kwargs) -> tuple[int, str]:
    """:func:`tempfile.mkstemp` whose file has mode ``0o666 & ~umask`` (as ``open()`` creates files)."""
    fd, tmp = tempfile.mkstemp(**kwargs)
    try:
        os.fchmod(fd, 0o666 & ~user_umask())
    except OSError:
        pass
    return fd, tmp
