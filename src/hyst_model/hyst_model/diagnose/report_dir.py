"""Where a report goes: the directory policy of :func:`~.report.write_report` (a directory holding the user's files
or another command's report is refused unless ``force``; a previous report of the same command is replaced) and
the move of a finished report into place (:func:`commit_report`)."""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import HystError
from ..io.modes import user_umask

__all__ = ["MARKER", "OURS", "check_report_dir", "commit_report"]

#: A file hyst writes into every report directory; a directory without it but with other files is not ours.
MARKER = ".hyst-report"
OURS = {"index.html", "time.png", "loop.png", "residual.png", "spectrum.png", "correlation.png", "ladder.png",
        MARKER}


def _marker_kind(d: Path) -> str | None:
    """The command whose report ``d`` holds (``compare``, ``diagnose``), None for a marker without one."""
    try:
        words = (d / MARKER).read_text().split()
    except OSError:
        return None
    return words[3].rstrip(";") if len(words) > 3 and words[:3] == ["written", "by", "hyst"] else None


def check_report_dir(path: str | os.PathLike, force: bool = False, kind: str = "report") -> Path:
    """Raise now, before any work, if ``path`` cannot take the report of ``kind`` (``compare``, ``diagnose``).

    Refused without ``force``: a directory holding files hyst did not write, and another command's report (``hyst
    compare`` and ``hyst diagnose`` into one directory: the second replaced the first's report without a word).
    The same command's report there is replaced (a re-run).

    Raises
    ------
    HystError
        ``path`` is a file, or a directory refused as above.
    """
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise HystError(f"report directory {d} is a file")
    if d.is_dir() and not force:
        names = {p.name for p in d.iterdir()}
        foreign = sorted(names - OURS)
        if names and MARKER not in names:
            raise HystError(f"report directory {d} is not empty and not a hyst report "
                            f"(e.g. {', '.join(foreign[:3]) or ', '.join(sorted(names)[:3])}); "
                            "choose another directory or pass --force")
        if foreign:
            raise HystError(f"report directory {d} holds files hyst did not write ({', '.join(foreign[:3])}); "
                            "choose another directory or pass --force")
        other = _marker_kind(d) if MARKER in names else None
        if other is not None and other != kind:
            raise HystError(f"report directory {d} holds a hyst {other} report; give the {kind} report its own "
                            "directory or pass --force to replace it")
    return d


def commit_report(stage: Path, target: Path) -> None:
    """Move the finished report from ``stage`` into ``target``: by one rename where it is new, else file by file
    (index.html last) after removing the previous report's plots that this one does not have."""
    if not target.exists():
        os.chmod(stage, 0o777 & ~user_umask())  # mkdtemp makes it 0700; a plain mkdir would not
        os.rename(stage, target)
        return
    try:
        for name in OURS - {MARKER}:
            if not (stage / name).exists():
                (target / name).unlink(missing_ok=True)
        for p in sorted(stage.iterdir(), key=lambda p: p.name == "index.html"):
            os.replace(p, target / p.name)
    except OSError as err:
        raise HystError(f"cannot replace the report in {target}: {err}") from err
