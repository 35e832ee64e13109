"""How a command prints its result: JSON under ``--json``, else text, and never lost to a write.

Command modules reach these names through :mod:`workbench.cli.common`.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import Any

from workbench.fileutil import strict_json

__all__ = ["emit", "emit_after_writing"]


def emit_after_writing(
    args: argparse.Namespace,
    obj: dict[str, Any],
    text: Callable[[dict[str, Any]], str],
    write: Callable[[dict[str, Any]], None] | None,
) -> None:
    """Write the command's files, then print its result; an unwritten result is still printed.

    A result that took minutes must not be lost to a full disk or a folder turned read-only:
    when ``write`` fails, the result is printed as it stands (under ``--json`` with the
    error's sentence under ``"error"``, so stdout keeps one JSON object) before the error
    ends the command with its status.

    Parameters
    ----------
    args : argparse.Namespace
    obj : dict
        The JSON result; ``write`` adds the names of the files it wrote.
    text : callable
        The human summary of a JSON result.
    write : callable or None
        Writes the files (``--out``); None when there are none to write.
    """
    from workbench.errors import OutputError

    try:
        if write is not None:
            write(obj)
    except OutputError as err:
        emit(args, {**obj, "error": str(err)} if getattr(args, "json", False) else obj, text(obj))
        err.result_printed = True
        raise
    emit(args, obj, text(obj))


def emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    """Print the command's result: ``obj`` as strict JSON under ``--json``, else ``text``.

    Parameters
    ----------
    args : argparse.Namespace
    obj : dict
        The JSON result; a non-finite number is printed as null (a bare NaN is not JSON).
    text : str
        The human summary.
    """
    if getattr(args, "json", False):
        print(json.dumps(strict_json(obj), indent=2, allow_nan=False))
    else:
        print(text)
