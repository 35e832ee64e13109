"""The ``workbench`` command line: one module per command family.

:mod:`workbench.cli.main` builds the parser and dispatches; :mod:`workbench.cli.common` holds
what the commands share; every other module registers and runs one family of subcommands
and imports, from this package, :mod:`workbench.cli.common` only. The library does the work:
a command module turns flags into library calls and prints their results.
"""

from __future__ import annotations

from workbench.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
