"""The ``hyst`` command line: a dispatcher over subcommands.

Subcommands register themselves through the entry-point group ``hyst.commands``; each entry point names a
function ``register(subparsers) -> None`` that adds one subparser and sets ``func`` (``func(args) -> int``)
as its default. hyst_model registers fit, simulate, compare, diagnose; hyst_control excite; hyst_bringup
track and demo.
A :class:`~hyst_model.errors.HystError` becomes one clear message on stderr and exit code 2 — never a
traceback wall.
"""
from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from importlib.metadata import entry_points

from ..errors import HystError

__all__ = ["main", "build_parser"]

# Built-in subcommands of hyst_model itself (module:function); other packages use the entry-point group.
_BUILTIN = (
    "hyst_model.cli.fit:register",
    "hyst_model.cli.simulate:register",
    "hyst_model.cli.compare:register",
    "hyst_model.cli.diagnose:register",
)


def _load(spec: str):
    import importlib
    mod, _, fn = spec.partition(":")
    return getattr(importlib.import_module(mod), fn)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hyst",
        description="Hysteresis models, identification, diagnosis and control for smart-material actuators.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    seen: set[str] = set()
    specs = list(_BUILTIN) + [ep.value for ep in entry_points(group="hyst.commands")]
    for spec in specs:
        if spec in seen:
            continue
        seen.add(spec)
        try:
            _load(spec)(sub)
        except (ImportError, AttributeError) as err:
            # A missing optional subcommand must not take the whole command line down.
            print(f"hyst: warning: subcommand {spec} unavailable ({err})", file=sys.stderr)
    return parser


#: Path arguments every subcommand reads (attribute name → what it is), checked before any heavy import so a
#: mistyped path is answered at once (it took 1.6 s idle and 8–12 s under load behind the numerical imports).
_INPUT_PATHS = {"data": "no such file or bag", "params": "no such params file", "input": "no such file"}


def _missing_input(args: argparse.Namespace) -> str | None:
    import os
    for attr, what in _INPUT_PATHS.items():
        value = getattr(args, attr, None)
        if isinstance(value, str) and value and not os.path.exists(value):
            return f"{value}: {what}"
    return None


#: Output arguments (attribute → option) and every argument naming a file the command reads.
_OUTPUTS = {"out": "--out", "report": "--report"}
_READS = (*_INPUT_PATHS, "scenario", "effect_module")


def _same(a: str, b: str) -> bool:
    import os
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist yet: compare the paths themselves
        return os.path.realpath(a) == os.path.realpath(b)


def _output_conflict(args: argparse.Namespace) -> str | None:
    """An empty output or input path, an output that is one of the command's inputs (``--force`` would lose the
    data), or ``--out`` inside the ``--report`` directory: refused before any work, whatever ``--force`` says."""
    import os
    outs = {opt: getattr(args, a) for a, opt in _OUTPUTS.items() if getattr(args, a, None) is not None}
    for opt, path in outs.items():
        if not str(path).strip():
            return f"{opt} is empty: give a path"
    reads: list[str] = []
    for a in _READS:
        v = getattr(args, a, None)
        for x in (v if isinstance(v, list) else [v]):
            if isinstance(x, str):
                if not x.strip():
                    return f"--{a.replace('_', '-')} is empty: give a path"
                reads.append(x)
    for opt, path in outs.items():
        for r in reads:
            if _same(path, r):
                return f"{opt} {path} is the file the command reads ({r}); write the output elsewhere"
    if "--out" in outs and "--report" in outs:
        o, rep = os.path.realpath(outs["--out"]), os.path.realpath(outs["--report"])
        if o == rep or o.startswith(rep + os.sep):
            return f"--out {outs['--out']} would be inside the --report directory {outs['--report']}; choose another"
    return None


@contextlib.contextmanager
def _watch_sigint():
    """Raise KeyboardInterrupt on SIGINT as Python does, and remember it (a non-empty list) for the rare signal
    that lands where Python ignores the exception (a weakref callback: the run went on and exited 0). The
    previous handler is back afterwards."""
    seen: list = []

    def on_sigint(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt
    try:
        ours = (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler)  # not where a caller chose
        if ours:
            signal.signal(signal.SIGINT, on_sigint)
    except (ValueError, OSError):
        ours = False
    try:
        yield seen
    finally:
        if ours:
            signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    missing = _missing_input(args) or _output_conflict(args)
    if missing:
        print(f"hyst {args.command}: error: {missing}", file=sys.stderr)
        return 2
    try:
        with _watch_sigint() as interrupted:
            code = int(args.func(args) or 0)
        if interrupted:  # Python drops a KeyboardInterrupt raised inside a weakref callback (matplotlib's)
            print(f"hyst {args.command}: interrupted too late to stop: the run finished, and the outputs it "
                  "names were written", file=sys.stderr)
            return 130
        return code
    except HystError as err:
        print(f"hyst {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hyst {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `hyst fit ... | head`: the reader has what it wanted; no traceback, no retry
        import os
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python flushes stdout at exit: into the void, not the pipe
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
