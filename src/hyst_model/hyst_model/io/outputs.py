"""Output files checked before the work: refuse an existing target at once, not after minutes of fitting
(the user's umask on the written file is :mod:`.modes`' job)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import ParamsError

__all__ = ["check_output"]


def check_output(path: str | Path, *, force: bool = False, what: str = "output", directory: bool = False) -> Path:
    """Raise :class:`ParamsError` now if ``path`` cannot be written later.

    Refuses an existing target without ``force``, a special file (``/proc/...``, devices, FIFOs), a missing or
    unwritable parent directory, and a target of the wrong kind (file vs directory).
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if str(path.resolve()).startswith(("/proc/", "/sys/", "/dev/")):
        raise ParamsError(f"{what} {path}: not a regular file location (special file system)")
    try:
        st = path.stat()
    except FileNotFoundError:
        st = None
    except OSError as err:
        raise ParamsError(f"{what} {path}: {err.strerror or err}") from err
    if st is not None:
        if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
            raise ParamsError(f"{what} {path} is not a regular file or directory")
        if directory != stat.S_ISDIR(st.st_mode):
            kind = "a directory, not a file" if stat.S_ISDIR(st.st_mode) else "a file, not a directory"
            raise ParamsError(f"{what} {path} is {kind}")
        if not force:
            raise ParamsError(f"{what} {path} exists; use --force to overwrite it")
    if not parent.is_dir():
        raise ParamsError(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ParamsError(f"{what} {path}: directory {parent} is not writable")
    try:
        if os.statvfs(parent).f_flag & os.ST_RDONLY:
            raise ParamsError(f"{what} {path}: {parent} is on a read-only file system")
    except (OSError, AttributeError):
        pass
    return path
