"""The ``hyst`` command line (argparse subcommands; see :mod:`hyst_model.cli.main`)."""
from .main import build_parser, main

__all__ = ["main", "build_parser"]
